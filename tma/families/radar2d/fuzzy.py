"""A small zero-order Sugeno fuzzy system: membership functions, a rule base, product AND and
weighted-average output.

Each rule names one linguistic term per input and a constant consequent; a rule's firing
strength is the product of its terms' memberships, and the output is the firing-weighted
average of the consequents.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


def sigmoid(a: float, c: float) -> Callable:
    """Membership 1 / (1 + exp(-a (u - c))): rises through 0.5 at u = c with slope a/4."""
    return lambda u: 1.0 / (1.0 + np.exp(-a * (np.asarray(u, float) - c)))


def complement(mu: Callable) -> Callable:
    return lambda u: 1.0 - mu(u)


@dataclass
class ZeroOrderSugeno:
    terms: dict[str, Callable]  # term name -> membership function
    rules: list[tuple[tuple[str, ...], float]]  # (term per input, consequent constant)

    def firing(self, inputs):
        """Firing strengths (n, n_rules) for inputs (n, n_inputs) (product AND)."""
        inputs = np.atleast_2d(np.asarray(inputs, float))
        memberships = {name: mu(inputs) for name, mu in self.terms.items()}  # (n, n_inputs)
        strengths = np.ones((inputs.shape[0], len(self.rules)))
        for r, (antecedent, _) in enumerate(self.rules):
            for i, term in enumerate(antecedent):
                strengths[:, r] *= memberships[term][:, i]
        return strengths

    def __call__(self, inputs):
        """Weighted-average output (n,)."""
        w = self.firing(inputs)
        consequents = np.array([c for _, c in self.rules])
        return (w @ consequents) / w.sum(axis=1)


def memory_length_selector(J: int, a: float = 5.0, c: float = 1.5) -> ZeroOrderSugeno:
    """The ``fuzzy_mm`` rule base on normalised residuals L_2..L_J ("tracking quality" of the
    models with memory 2..J): for m = J..2, "Q_2..Q_m Good and Q_(m+1)..Q_J Bad -> m", and
    "all Bad -> 2". Bad(u) = 1 / (1 + exp(-a (u - c))), Good = 1 - Bad."""
    bad = sigmoid(a, c)
    n = J - 1
    rules = [(("good",) * (m - 1) + ("bad",) * (J - m), float(m)) for m in range(J, 1, -1)]
    rules.append((("bad",) * n, 2.0))
    return ZeroOrderSugeno({"bad": bad, "good": complement(bad)}, rules)
