"""Run independent shard tasks serially or with joblib, with a progress bar.

Results come back in task order whatever the number of workers, and each task computes with
one BLAS thread, so outputs do not depend on ``n_jobs``.
"""

from joblib import Parallel, delayed
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm


def _single_threaded(fn, task):
    with threadpool_limits(limits=1):
        return fn(task)


def run_tasks(fn, tasks, *, n_jobs: int = 1, desc: str = "", progress: bool = True):
    """Apply ``fn`` to each task; return the results in task order."""
    tasks = list(tasks)
    bar = tqdm(total=len(tasks), desc=desc, unit="shard", disable=not progress or not tasks)
    results = []
    if n_jobs == 1 or len(tasks) <= 1:
        for task in tasks:
            results.append(_single_threaded(fn, task))
            bar.update()
    else:
        parallel = Parallel(n_jobs=n_jobs, return_as="generator")
        for result in parallel(delayed(_single_threaded)(fn, t) for t in tasks):
            results.append(result)
            bar.update()
    bar.close()
    return results
