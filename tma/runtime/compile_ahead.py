"""Compiling a command's kernels ahead (``compile_ahead``): on a machine whose numba cache is
empty, each estimator of the command runs on a small log of its scenario in a process of its
own while the command goes on, so that the estimate stage's workers find the kernels compiled
(``tma.runtime.jit.compiling``) instead of each compiling them."""

AHEAD_TRACKS = 2  # tracks of the small log each estimator of a command runs on ahead
_AHEAD: set = set()  # the estimators compile_ahead started in this process


def compile_ahead(scenarios: list[dict], estimators: list[dict]):
    """Start compiling the kernels a command will run, in processes of their own forked from
    the command's worker server (``tma.runtime.forkserver``), while the command goes on
    (composing, simulating): on a machine whose numba cache is empty, the estimate stage's
    workers then find the kernels compiled, or wait for the compilation under way
    (``tma.runtime.jit.compiling``) instead of each compiling them. Each estimator config
    of ``estimators`` runs in a process of its own (their kernels compile side by side) on a
    log of ``AHEAD_TRACKS`` tracks of each scenario point of ``scenarios`` of its family (the
    same code paths, so the same kernels and argument types), unless numba's cache holds
    kernels of their families already (``compiled_before``: then nothing runs, and a kernel
    still missing is compiled by the first worker that needs it, once). Nothing is printed
    and failures are ignored: the stages run as they would without it. Started from a
    thread, so that the command does not wait for the server to be ready; None (nothing
    started) without a worker server (a Python session), without scenarios or when this
    process started it for these estimators before, else that thread."""
    from tma.runtime.forkserver import server_started

    names = {node.get("name") for node in estimators}
    if not server_started() or not scenarios or names <= _AHEAD:
        return None  # e.g. the next job of a multirun in this process: done by the first
    _AHEAD.update(names)
    import multiprocessing
    import threading

    process = multiprocessing.get_context("forkserver").Process(
        target=_compile_ahead, args=(scenarios, estimators), daemon=True,
        name="tma-compile-ahead")
    thread = threading.Thread(target=process.start, daemon=True)
    thread.start()
    return thread


def run_ahead(estimator, log) -> None:
    """One estimator over one small log, its output dropped: what compiles its kernels."""
    estimator.estimate(log)


def _compile_ahead(scenarios: list[dict], estimators: list[dict]) -> None:
    import os

    from tma.families import build_estimator, load_scenario
    from tma.runtime import jit

    built = []
    for node in estimators:
        try:
            built.append(build_estimator(node))  # imports its modules, and so their kernels
        except Exception:  # the command itself says what is wrong with it
            continue
    if all(jit.compiled_before(f"tma.families.{f}") for f in {e.family for e in built}):
        return  # this machine compiled them before: nothing to do ahead
    logs = []
    for node in scenarios:
        try:
            module, cfg = load_scenario({**node, "n_tracks": AHEAD_TRACKS,
                                         "shard_size": AHEAD_TRACKS})
            logs.append((cfg.own_family(), module.simulate_shard(cfg, 0)[0]))
        except Exception:
            continue
    children = []
    for i, estimator in enumerate(built):
        child = os.fork() if i < len(built) - 1 else 0  # the last runs in this process
        if child:
            children.append(child)
            continue
        try:
            for family, log in logs:
                if family == estimator.family:
                    run_ahead(estimator, log)
        except Exception:  # e.g. an estimator that needs its prepare (training)
            pass
        finally:
            if i < len(built) - 1:  # a forked process: ends here, whatever happened
                os._exit(0)
    for child in children:
        os.waitpid(child, 0)
