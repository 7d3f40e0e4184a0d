"""Directories that tma owns: plain names, a marker, build beside then swap in, one writer.

Every dataset and run directory is built in a hidden staging sibling ``.<name>.partial`` that
carries the marker file ``.tma-owned``; only when it is complete is it swapped in under
``<name>``, so an existing good output is replaced only by a complete new one and a failure
leaves the old one byte-identical. A killed run leaves the staging directory behind and the
next run resumes from it. Nothing is removed unless it carries the marker (or a tma
manifest): a mistyped path never deletes files that tma did not create. A lock file
``.<name>.lock`` (``flock``) serialises processes working on the same output. Every stage that
writes a dataset or a run (simulate, estimate, ingest) goes through ``building``: lock ->
recover -> stage -> swap.
"""

import contextlib
import fcntl
import json
import logging
import os
import re
import shutil
from pathlib import Path

from tma.errors import ConfigError, InputError

log = logging.getLogger(__name__)

MARKER = ".tma-owned"
MANIFEST_FORMATS = ("tma-dataset", "tma-run")
_PLAIN_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,199}")
_TEMPORARY = re.compile(r"\..+\.tmp-(\d+)")  # atomic_path's temporaries: .<name>.tmp-<pid>


def plain_name(name, what: str) -> str:
    """``name`` if it is a plain file name (letters, digits, ``.``, ``_``, ``-``; not starting
    with ``.``; at most 200 characters), else a ConfigError naming ``what``."""
    name = str(name)
    if not _PLAIN_NAME.fullmatch(name):
        raise ConfigError(f"{what}='{name}' is not a plain name: use letters, digits, '.', '_' "
                          "and '-' only (no path separator, not starting with '.')")
    return name


def is_owned(path) -> bool:
    """True if ``path`` is a directory tma created: it has the marker or a tma manifest, and
    it is not a symbolic link (tma never writes or deletes through a link)."""
    path = Path(path)
    if path.is_symlink():
        return False
    if (path / MARKER).is_file():
        return True
    try:
        return json.loads((path / "manifest.json").read_text()).get("format") in MANIFEST_FORMATS
    except (OSError, ValueError, AttributeError):
        return False


def remove_owned(path):
    """Remove directory ``path`` if tma created it; refuse (InputError) otherwise."""
    path = Path(path)
    if not path.exists():
        return
    if not is_owned(path):
        raise InputError(f"{path} was not created by tma (no {MARKER} marker): "
                         "refusing to delete or replace it")
    shutil.rmtree(path)


def remove_stale_temporaries(directory, only_dead=False, names=None):
    """Delete atomic-write temporaries (``.<name>.tmp-<pid>``) left by killed processes: below
    ``directory`` (a directory tma owns), or, given ``names``, only those of these file names
    directly in ``directory`` (a folder shared with the user, such as the tables folder).
    ``only_dead``: keep those whose process still runs."""
    directory = Path(directory)
    found = (directory.rglob(".*.tmp-*") if names is None else
             [p for name in names for p in directory.glob(f".{name}.tmp-*")])
    for path in found:
        match = _TEMPORARY.fullmatch(path.name)
        if (match and path.is_file() and not path.is_symlink()
                and not (only_dead and _alive(int(match.group(1))))):
            path.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def staging_dir(target, fresh=False) -> Path:
    """The staging sibling of ``target``, marked as tma's, stale temporaries removed.
    ``fresh``: start empty (``force``) instead of resuming what a killed run left."""
    target = Path(target)
    stage = target.with_name(f".{target.name}.partial")
    if stage.exists() and (fresh or not is_owned(stage)):
        remove_owned(stage)
    stage.mkdir(parents=True, exist_ok=True)
    (stage / MARKER).write_text("created by tma; safe to delete when no tma process runs\n")
    remove_stale_temporaries(stage)
    return stage


def adopt_broken(target, stage) -> None:
    """Move an incomplete or damaged ``target`` into the (empty) staging place so that its
    finished pieces are reused; a good target is never passed here."""
    if Path(target).exists() and not Path(stage).exists():
        if not is_owned(target):
            raise InputError(f"{target} was not created by tma: refusing to replace it")
        os.replace(target, stage)


def swap_in(stage, target) -> Path:
    """Put the complete ``stage`` in place of ``target`` (which must be tma's if present)."""
    stage, target = Path(stage), Path(target)
    remove_stale_temporaries(stage)
    if not target.exists():
        os.replace(stage, target)
        return target
    if not is_owned(target):
        raise InputError(f"{target} was not created by tma: refusing to replace it")
    old = target.with_name(f".{target.name}.old-{os.getpid()}")
    os.replace(target, old)
    os.replace(stage, target)
    shutil.rmtree(old)
    return target


def recover(target) -> None:
    """Undo what a process killed inside ``swap_in`` left: restore the previous version if
    the target is missing, and delete older versions that were already replaced."""
    target = Path(target)
    olds = sorted(p for p in target.parent.glob(f".{target.name}.old-*") if is_owned(p))
    if target.is_symlink():
        raise InputError(f"{target} is a symbolic link: tma does not write through links; "
                         "choose another name")
    if olds and not target.exists():
        os.replace(olds.pop(), target)
    for old in olds:
        shutil.rmtree(old)


@contextlib.contextmanager
def locked(targets):
    """Hold an exclusive lock on each of ``targets`` (taken in sorted order, so two
    processes never wait for each other in a cycle); a second process waits its turn."""
    with contextlib.ExitStack() as stack:
        for target in sorted({Path(t) for t in targets}):
            target.parent.mkdir(parents=True, exist_ok=True)
            handle = stack.enter_context(open(target.with_name(f".{target.name}.lock"), "a"))
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                log.info("waiting for another tma process working on %s", target)
                fcntl.flock(handle, fcntl.LOCK_EX)
        yield


class Building:
    """The outputs ``building`` holds: ``stage`` one of them, ``swap`` it in when complete."""

    def __init__(self, targets, resume: bool):
        self.targets, self.resume, self.stages = [Path(t) for t in targets], resume, {}

    def stage(self, target, fresh: bool = False, adopt: bool = False) -> Path:
        """The staging directory of ``target`` (``staging_dir``): empty when ``fresh``, else
        what a killed process left; ``adopt``: an incomplete or damaged ``target`` is moved
        there first, its finished pieces reused (``adopt_broken``)."""
        target = Path(target)
        if adopt and not fresh:
            adopt_broken(target, target.with_name(f".{target.name}.partial"))
        self.stages[target] = staging_dir(target, fresh=fresh)
        return self.stages[target]

    def swap(self, target) -> Path:
        """Put the complete stage of ``target`` in its place (``swap_in``)."""
        return swap_in(self.stages.pop(Path(target)), target)


@contextlib.contextmanager
def building(targets, resume: bool = True):
    """Lock -> recover -> stage -> swap, for the outputs at ``targets`` (datasets, runs):
    held exclusively (``locked``: a second process waits), each recovered from a swap a
    killed process left (``recover``); the block stages and swaps them with the ``Building``
    it is given. Stages the block leaves unswapped when it fails are kept for the next run to
    resume (``resume``), or removed."""
    with locked(targets):
        for target in targets:
            recover(target)
        outputs = Building(targets, resume)
        try:
            yield outputs
        except BaseException:
            if not resume:
                for stage in outputs.stages.values():
                    remove_owned(stage)
            raise
