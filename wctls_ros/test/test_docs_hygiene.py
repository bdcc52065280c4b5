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

TRACKER = 'a tracker number no reader can see'
PATH = 'a path of our machines'
# "issue 17", "Issue 17's", "issues 14 and 15", "issue #3", "the issue-18 targets", also with
# the number wrapped onto the next line.
_TRACKER_NUMBER = re.compile(r'\b[Ii]ssues?(?:-|\s+)#?[0-9]+')
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
        text = data.decode('utf-8', 'replace')
        lines = text.split('\n')
        for pattern, what in ((_TRACKER_NUMBER, TRACKER), (_MACHINE_PATH, PATH)):
            for match in pattern.finditer(text):
                number = text.count('\n', 0, match.start()) + 1
                found.append((str(name), number, f'{what} ({match.group(0)!r}): '
                              f'{lines[number - 1].strip()}'))
    return [f'{name}:{number}: {what}' for name, number, what in sorted(found)]


def test_no_machine_paths_and_no_tracker_numbers_outside_the_changelogs():
    files = tracked_files(REPOSITORY)
    assert any(name.suffix == '.md' for name in files) and any(
        name.suffix == '.py' for name in files)
    found = findings(REPOSITORY, files)
    assert not found, ('say what it is, not where it was on our machine or which issue asked '
                       'for it (the history goes into CHANGELOG.rst):\n' + '\n'.join(found))


@pytest.mark.parametrize('text,expected', [
    ('    # The baseline of issue 13.', f"page.md:3: {TRACKER} ('issue 13')"),
    ('Issues 14 and 15 are met.', f"page.md:3: {TRACKER} ('Issues 14')"),
    ('The issue-18 targets', f"page.md:3: {TRACKER} ('issue-18')"),
    ('see issue #7', f"page.md:3: {TRACKER} ('issue #7')"),
    ('as the\n  issue 12 asks', f"page.md:4: {TRACKER} ('issue 12')"),
    ('the targets of issue\n  12', f"page.md:3: {TRACKER} ('issue\\n  12')"),
    ('--peer /work/peer/bin/lle_bench', f"page.md:3: {PATH} ('/work/')"),
    ('--baseline /tmp/base17', f"page.md:3: {PATH} ('/tmp/b')"),
    ('(in /root)', f"page.md:3: {PATH} ('/root')"),
    ('cd /home/ubuntu/ws', f"page.md:3: {PATH} ('/home/u')"),
])
def test_a_tracker_number_or_a_machine_path_is_found_with_its_file_and_line(
        text, expected, tmp_path):
    (tmp_path / 'page.md').write_text(f'# A page\n\n{text}\n')
    (found,) = findings(tmp_path, [pathlib.Path('page.md')])
    assert found.startswith(expected + ': '), found


@pytest.mark.parametrize('line', [
    'An issue with 3 beams.',                      # "issue" and a number, no reference
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


def test_outside_a_git_checkout_every_file_but_the_builds_and_the_changelogs_is_checked(
        tmp_path):
    for name in ('docs/page.md', 'build/x.md', 'install/y.py', '.venv/z.py', 'CHANGELOG.rst',
                 'pkg/CHANGELOG.rst', 'pkg/node.py'):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text('text\n')
    assert tracked_files(tmp_path) == [pathlib.Path('docs/page.md'), pathlib.Path('pkg/node.py')]
