"""What the workers' fork server (``tma.runtime.forkserver.preload_workers``) imports, and so
every worker forked from it has from its start; imported there only (its import does the work).

The modules named in ``$TMA_PRELOAD`` (comma-separated), each on its own: one that fails to
import (a broken plotting backend, say) is left to the worker that needs it, which then
reports the real error, where multiprocessing's server would die of anything but an
ImportError and leave the command only an EOFError.

The server, and each worker it forks, ends with its parent (Linux's parent-death signal): a
command killed outright (SIGKILL, the out-of-memory killer) leaves no server and no worker
computing on, and so nothing holding the shared-memory semaphores their trackers then free.

numba's compiler is not set up here, measured: it would spare each worker ~0.4 s at its first
compiled call, but delay the server's first fork by as much, which every command pays and
only those that estimate with compiled kernels win back."""

import importlib
import os

from tma.runtime.forkserver import FORK_SERVER, PRELOAD, die_with_parent

die_with_parent(int(os.environ.get(FORK_SERVER) or 0))  # the command that started the server
_forking = [0]  # the pid of the process that forks (the server; a worker, for its children)
os.register_at_fork(before=lambda: _forking.__setitem__(0, os.getpid()),
                    after_in_child=lambda: die_with_parent(_forking[0]))

for _name in filter(None, os.environ.get(PRELOAD, "").split(",")):
    try:
        importlib.import_module(_name)
    except Exception:  # the worker that needs it imports it again and says why
        continue
