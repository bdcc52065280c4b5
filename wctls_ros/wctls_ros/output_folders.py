# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Output folders a tool owns: it writes into a folder of its own, or refuses with one line.

Every output folder of ``demo``, ``score`` and ``evaluate`` holds a marker file, ``.<tool>``
(e.g. ``.score``), that lists the files the tool wrote there, as process_bag's ``.process_bag``
does. A tool writes into a folder only when the folder is missing (the tool makes it), empty,
or marked by the same tool and holding nothing but the files the marker lists (an earlier run
of the tool, which the new run replaces). The marker records each entry's inode when the tool
wrote it: an entry that is not the one the tool wrote (a marker copied or written by hand, a
file replaced since) is the user's, and the folder is refused. Any other folder, a file of
that name, or a folder marked by another tool is refused with a
:class:`~wctls_ros.cli.UserError` that says why, and nothing in it is touched. The staging
folder of a run that was killed (SIGKILL, a power cut) is removed by the next run of the tool
on that output. Pure Python: no rclpy import.
"""

import contextlib
import json
import os
import pathlib
import shutil
from typing import Iterable, List, Optional

from .cli import staged_folder, UserError


def marker_name(tool: str) -> str:
    """
    Return the name of a tool's marker file.

    :param tool: the tool's name, e.g. 'score'
    :return: e.g. '.score'
    """
    return f'.{tool}'


def claim(out, tool: str) -> List[str]:
    """
    Check that a tool may write into a folder; return what its earlier output there holds.

    :param out: the output folder
    :param tool: the tool's name
    :return: the names of the entries of an earlier output of the tool in ``out`` (the new
        output replaces them), empty when ``out`` is missing or empty
    :raises UserError: when ``out`` is not the tool's to write (one line: why, and what to do)
    """
    out = pathlib.Path(out)
    if not out.exists() and not out.is_symlink():
        return []
    if not out.is_dir():
        raise UserError(f'{out} exists and is not a folder: choose another output folder')
    present = sorted(path.name for path in out.iterdir())
    if not present:
        return []
    marker = out / marker_name(tool)
    try:
        document = json.loads(marker.read_text())
        written = set(document['files'])
        identities = dict(document['identities'])
    except (OSError, ValueError, KeyError, TypeError):
        raise UserError(f'{out} is not an output folder of {tool} (it holds '
                        f'{_some(present)} and no {marker.name} file {tool} wrote): refusing to '
                        'write into it; choose a new or empty folder') from None
    others = [name for name in present if name not in written
              or name != marker.name and identities.get(name) != _inode(out / name)]
    if others:
        raise UserError(f'{out} holds files {tool} did not write ({_some(others)}): refusing to '
                        'write into it; remove them or choose a new or empty folder')
    return present


def _inode(path: pathlib.Path) -> Optional[int]:
    """
    Return what tells an entry from another of the same name: its inode (None when missing).

    :param path: the entry (a link is not followed)
    :return: the inode number, or None
    """
    try:
        return os.lstat(path).st_ino
    except FileNotFoundError:
        return None


def _some(names: List[str]) -> str:
    """Return up to three names, and how many more."""
    shown = ', '.join(names[:3])
    return shown + (f' and {len(names) - 3} more' if len(names) > 3 else '')


def mark(folder, tool: str, names: Iterable[str]) -> None:
    """
    Write a tool's marker file into a folder, listing the entries the tool writes there.

    Each entry's inode is recorded as it is now (None for one not yet written): mark again once
    the entries are written, or the next run refuses them.

    :param folder: the folder
    :param tool: the tool's name
    :param names: the entries' names (the marker is listed too)
    """
    marker = marker_name(tool)
    files = sorted({marker, *names})
    pathlib.Path(folder, marker).write_text(json.dumps(
        {'written_by': f'{tool} of wctls_ros', 'files': files, 'pid': os.getpid(),
         'identities': {name: _inode(pathlib.Path(folder, name))
                        for name in files if name != marker}}) + '\n')


def remove_entries(folder, names: Iterable[str]) -> None:
    """
    Remove entries of a folder (files, symbolic links, folders); missing ones are skipped.

    :param folder: the folder
    :param names: the entries' names
    """
    for name in names:
        path = pathlib.Path(folder, name)
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()


@contextlib.contextmanager
def owned_folder(out, tool: str):
    """
    Yield a staging folder whose files become ``out`` once the block ends without error.

    ``out`` is claimed first (:func:`claim`: refused unless missing, empty or the tool's own),
    and the staging folders of the tool's killed runs on ``out`` are removed. The staging folder
    is marked at once (with this process's id); the files then move in as
    :func:`~wctls_ros.cli.staged_folder` moves them, with the marker, and what an earlier output
    of the tool held beyond the new files is removed.

    :param out: the output folder
    :param tool: the tool's name
    :return: the staging folder (a context manager's value)
    :raises UserError: when ``out`` is not the tool's to write
    :raises OSError: when a folder cannot be created or a file cannot be moved into place
    """
    earlier = claim(out, tool)
    _remove_killed_stagings(pathlib.Path(out), tool)
    with staged_folder(out) as staging:
        mark(staging, tool, [])
        yield staging
        written = [path.name for path in staging.iterdir()]
        mark(staging, tool, written)
    remove_entries(out, sorted(set(earlier) - set(written) - {marker_name(tool)}))


def _remove_killed_stagings(out: pathlib.Path, tool: str) -> None:
    """
    Remove the staging folders of the tool's runs on ``out`` whose process is gone.

    A staging folder is the tool's when it holds the tool's marker (written first), with the
    id of the process that staged it; a live process's folder is left alone.

    :param out: the output folder
    :param tool: the tool's name
    """
    for staging in out.parent.glob(f'.partial-{out.name}-*'):
        try:
            document = json.loads((staging / marker_name(tool)).read_text())
            pid = int(document['pid'])
        except (OSError, ValueError, KeyError, TypeError):
            continue                # not a staging of this tool's
        if document.get('written_by') == f'{tool} of wctls_ros' and not _running(pid):
            shutil.rmtree(staging, ignore_errors=True)


def _running(pid: int) -> bool:
    """Return whether a process of this id exists (another user's too)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
