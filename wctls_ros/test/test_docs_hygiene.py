# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Nothing a reader cannot follow: no paths of our machines, no numbers of a private tracker.

Every tracked text file (docs, README, code and its comments, scripts) is checked but the
changelogs (``CHANGELOG.rst``), where a change's history belongs, and this module, whose examples
are what it looks for. A reader cannot open a folder of the machine a figure was measured on,
nor see "issue 17": say what the thing is instead (a build of commit X, the reason for a rule).
"""

import pathlib
import re
import subprocess

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
EXEMPT_NAMES = ('CHANGELOG.rst',)
# This module's own examples are what it looks for.
THIS_MODULE = pathlib.Path(__file__).resolve()
# Outside a git checkout: the top-level folders the build and its tools write.
UNTRACKED_FOLDERS = ('build', 'install', 'log', 'out')

# "issue 17", "Issue 17's", "issues 14 and 15", "issue #3", "the issue-18 targets".
_TRACKER_NUMBER = re.compile(r'\b[Ii]ssues?[ -]#?[0-9]+')
# A path of the development machines: /work/..., /tmp/<name>, /root, /home/<user>,
# /Users/<user>; not a URL's path (example.org/work/) nor a relative one (docs/work/).
_MACHINE_PATH = re.compile(r'(?<![\w.~/-])/(?:work/|tmp/\w|root\b|home/\w|Users/\w)')


def tracked_files(repository: pathlib.Path) -> list:
    """
    Return the files of the repository that are not exempt, relative to it.

    :param repository: the checkout's top folder
    :return: the tracked files (``git ls-files``), or every file outside dot-folders and the
        build's folders when the tree is no git checkout
    """
    listing = subprocess.run(['git', 'ls-files', '-z'], cwd=repository, capture_output=True)
    if listing.returncode == 0:
        paths = [pathlib.Path(name) for name in listing.stdout.decode().split('\0') if name]
    else:
        paths = [path.relative_to(repository) for path in repository.rglob('*')
                 if path.is_file()]
        paths = [path for path in paths if path.parts[0] not in UNTRACKED_FOLDERS
                 and not any(part.startswith('.') for part in path.parts[:-1])]
    return sorted(path for path in paths if path.name not in EXEMPT_NAMES
                  and (repository / path).resolve() != THIS_MODULE)


def findings(repository: pathlib.Path, files) -> list:
    """
    Return one ``file:line: what`` for every machine path and tracker number in ``files``.

    :param repository: the checkout's top folder
    :param files: paths relative to it; binary files (with a NUL byte) are skipped
    :return: the findings, in file and line order
    """
    found = []
    for name in files:
        path = repository / name
        if not path.is_file():                  # deleted in the work tree, not yet in git
            continue
        data = path.read_bytes()
        if b'\0' in data:
            continue
        for number, line in enumerate(data.decode('utf-8', 'replace').splitlines(), 1):
            for pattern, what in ((_TRACKER_NUMBER, 'a tracker number no reader can see'),
                                  (_MACHINE_PATH, 'a path of our machines')):
                match = pattern.search(line)
                if match:
                    found.append(f'{name}:{number}: {what} ({match.group(0)!r}): '
                                 f'{line.strip()}')
    return found


def test_no_machine_paths_and_no_tracker_numbers_outside_the_changelogs():
    files = tracked_files(REPOSITORY)
    assert any(name.suffix == '.md' for name in files) and any(
        name.suffix == '.py' for name in files)
    found = findings(REPOSITORY, files)
    assert not found, ('say what it is, not where it was on our machine or which issue asked '
                       'for it (the history goes into CHANGELOG.rst):\n' + '\n'.join(found))


@pytest.mark.parametrize('line,expected', [
    ('    # The baseline of issue 13.', "'issue 13'"),
    ('Issues 14 and 15 are met.', "'Issues 14'"),
    ('The issue-18 targets', "'issue-18'"),
    ('see issue #7', "'issue #7'"),
    ('--peer /work/peer/bin/lle_bench', "'/work/'"),
    ('--baseline /tmp/base17', "'/tmp/b'"),
    ('(in /root)', "'/root'"),
    ('cd /home/ubuntu/ws', "'/home/u'"),
])
def test_a_tracker_number_or_a_machine_path_is_found_with_its_file_and_line(
        line, expected, tmp_path):
    (tmp_path / 'page.md').write_text(f'# A page\n\n{line}\n')
    (found,) = findings(tmp_path, [pathlib.Path('page.md')])
    assert found.startswith('page.md:3: ') and expected in found, found


@pytest.mark.parametrize('line', [
    'An issue with 3 beams.',                      # a number after "issue", not a reference
    'https://example.org/work/results and docs/tmp/x',
    'cd ~/ros2_ws && /dev/ttyUSB0 and /opt/ros/jazzy',
    'tempfile.gettempdir() / "x"',
])
def test_other_numbers_and_paths_are_no_finding(line, tmp_path):
    (tmp_path / 'page.md').write_text(line + '\n')
    assert findings(tmp_path, [pathlib.Path('page.md')]) == []


def test_binary_files_are_skipped(tmp_path):
    (tmp_path / 'bag.db3').write_bytes(b'SQLite\0' + b' /tmp/x issue 3')
    assert findings(tmp_path, [pathlib.Path('bag.db3')]) == []
