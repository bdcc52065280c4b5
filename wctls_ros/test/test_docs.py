# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The documentation stays true to the code and to itself.

The parameter tables of docs/user_guide.md are the schema's (``python -m wctls_ros.params
--check``), every relative link and #anchor of the Markdown pages leads somewhere, the README
stays a landing page, and the release files (CITATION.cff, CHANGELOG.rst) parse as their tools
read them and name this version of the packages.
"""

import pathlib
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

from catkin_pkg.changelog import get_changelog_from_path
import pytest
import yaml

REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
USER_GUIDE = REPOSITORY / 'docs' / 'user_guide.md'
PAGES = sorted([REPOSITORY / 'README.md', REPOSITORY / 'CONTRIBUTING.md',
                *(REPOSITORY / 'docs').glob('*.md')])
PACKAGES = ('wctls_ros', 'wctls_rplidar', 'wctls_lab', 'wctls_msgs')
README_MAX_LINES = 200

# [text](target) and ![alt](target), the target without an optional "title".
_LINK = re.compile(r'!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+"[^"]*")?\s*\)')
_FENCE = re.compile(r'^\s*(```|~~~)')
_CODE_SPAN = re.compile(r'(`+)(?:(?!\1).)+?\1')
_HEADING = re.compile(r'^(#{1,6})\s+(.*?)\s*#*\s*$')


def _prose_lines(text: str):
    """Yield (line number, line) of the lines outside fenced and indented code blocks."""
    fenced = False
    for number, line in enumerate(text.splitlines(), 1):
        if _FENCE.match(line):
            fenced = not fenced
            continue
        if fenced or line.startswith('    ') and not line.lstrip().startswith(('|', '-', '*')):
            continue
        yield number, line


def _slug(heading: str) -> str:
    """Return GitHub's anchor of a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r'\[([^\]]*)\]\([^)]*\)', r'\1', heading)      # a link keeps its text
    text = text.replace('`', '').strip().lower()
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


def anchors(path: pathlib.Path) -> set:
    """Return every anchor GitHub gives the headings of a Markdown page (-1, -2 for repeats)."""
    found, seen = set(), {}
    for _, line in _prose_lines(path.read_text(encoding='utf-8')):
        match = _HEADING.match(line)
        if match:
            slug = _slug(match[2])
            count = seen.get(slug, 0)
            seen[slug] = count + 1
            found.add(slug if count == 0 else f'{slug}-{count}')
    return found


def broken_links(page: pathlib.Path) -> list:
    """Return 'line N: target (reason)' for each relative link of a page that leads nowhere."""
    broken = []
    for number, line in _prose_lines(page.read_text(encoding='utf-8')):
        for target in _LINK.findall(_CODE_SPAN.sub('', line)):
            if re.match(r'^[a-z][a-z0-9+.-]*:', target):           # http:, https:, mailto:
                continue
            path_part, _, anchor = target.partition('#')
            path = (page.parent / path_part).resolve() if path_part else page
            if not path.exists():
                broken.append(f'line {number}: {target} (no such file)')
            elif anchor and path.suffix == '.md' and anchor not in anchors(path):
                broken.append(f'line {number}: {target} (no heading #{anchor} in {path.name})')
    return broken


def _params_cli(*arguments):
    return subprocess.run([sys.executable, '-m', 'wctls_ros.params', *arguments],
                          capture_output=True, text=True, timeout=60)


def _version(package: str) -> str:
    return ET.parse(REPOSITORY / package / 'package.xml').getroot().findtext('version')


def test_the_user_guide_tables_are_the_schemas():
    result = _params_cli('--check', str(USER_GUIDE))
    assert result.returncode == 0, result.stderr


def test_a_stale_table_is_found_and_rewritten(tmp_path):
    current = USER_GUIDE.read_text(encoding='utf-8')
    row = '| `marker_line_width_m` | double | 0.02 |'
    assert current.count(row) == 1
    stale = tmp_path / 'guide.md'
    stale.write_text(current.replace(row, '| `marker_line_width_m` | double | 0.03 |'),
                     encoding='utf-8')

    checked = _params_cli('--check', str(stale))
    assert checked.returncode == 1
    assert f'--write {stale}' in checked.stderr
    assert _params_cli('--write', str(stale)).returncode == 0
    assert stale.read_text(encoding='utf-8') == current


def test_a_document_without_a_nodes_markers_is_a_user_error(tmp_path):
    document = tmp_path / 'guide.md'
    document.write_text('<!-- params:feature_node -->\n\n<!-- /params:feature_node -->\n',
                        encoding='utf-8')
    result = _params_cli('--write', str(document))
    assert result.returncode == 2
    assert 'bag_replay' in result.stderr and 'Traceback' not in result.stderr
    assert result.stderr.count('\n') == 1


def test_every_page_to_check_exists():
    names = {str(page.relative_to(REPOSITORY)) for page in PAGES}
    assert {'README.md', 'CONTRIBUTING.md', 'docs/user_guide.md', 'docs/results.md',
            'docs/architecture.md', 'docs/performance.md', 'docs/derivation.md'} <= names


@pytest.mark.parametrize('page', PAGES, ids=lambda page: str(page.relative_to(REPOSITORY)))
def test_every_relative_link_and_anchor_resolves(page):
    assert broken_links(page) == []


def test_the_link_check_finds_a_missing_file_and_a_missing_anchor(tmp_path):
    (tmp_path / 'other.md').write_text('# A `code` title: with punctuation\n\n## Repeat\n'
                                       '## Repeat\n', encoding='utf-8')
    page = tmp_path / 'page.md'
    page.write_text('[ok](other.md#a-code-title-with-punctuation) [ok](other.md#repeat-1)\n'
                    '[gone](missing.md) [bad](other.md#nowhere) [web](https://example.org/x)\n'
                    '`[not a link](missing.md)`\n\n```\n[not a link](missing.md)\n```\n',
                    encoding='utf-8')
    assert broken_links(page) == ['line 2: missing.md (no such file)',
                                  'line 2: other.md#nowhere (no heading #nowhere in other.md)']


def test_the_readme_is_a_landing_page():
    readme = (REPOSITORY / 'README.md').read_text(encoding='utf-8')
    assert len(readme.splitlines()) < README_MAX_LINES
    for page in ('docs/user_guide.md', 'docs/results.md', 'docs/architecture.md',
                 'docs/performance.md', 'docs/derivation.md', 'CITATION.cff'):
        assert f']({page}' in readme, f'the README does not link {page}'
    assert 'make demo' in readme and 'make test' in readme
    assert 'doi:10.32604/cmes.2026.080540' in readme


def test_the_citation_file_has_what_cff_requires_and_this_version():
    citation = yaml.safe_load((REPOSITORY / 'CITATION.cff').read_text(encoding='utf-8'))
    assert citation['cff-version'] == '1.2.0'
    assert citation['message'] and citation['title'] and citation['type'] == 'software'
    assert citation['authors'] and all('name' in author or 'family-names' in author
                                       for author in citation['authors'])
    assert str(citation['version']) == _version('wctls_ros')
    assert citation['license'] == 'Apache-2.0'
    paper, = citation['references']
    assert paper['type'] == 'article' and paper['doi'] == '10.32604/cmes.2026.080540'
    assert len(paper['authors']) == 6 and paper['year'] == 2026


@pytest.mark.filterwarnings('ignore:nodes.Node.traverse:DeprecationWarning')
@pytest.mark.parametrize('package', PACKAGES)
def test_each_package_has_a_changelog_catkin_reads(package):
    path = REPOSITORY / package / 'CHANGELOG.rst'
    changelog = get_changelog_from_path(str(path), package)
    assert changelog is not None and changelog.package_name == package
    text = path.read_text(encoding='utf-8')
    title = f'Changelog for package {package}'
    assert text.startswith(f"{'^' * len(title)}\n{title}\n{'^' * len(title)}\n")
    # catkin_generate_changelog's sections: 'Forthcoming', then 'X.Y.Z (YYYY-MM-DD)', newest
    # first; a released version is never newer than package.xml's.
    sections = re.findall(r'^(.+)\n-+$', text, re.MULTILINE)
    assert sections and all(re.fullmatch(r'Forthcoming|\d+\.\d+\.\d+ \(\d{4}-\d{2}-\d{2}\)', s)
                            for s in sections)
    released = [tuple(map(int, v.split('.'))) for v, _ in changelog.foreach_version()]
    assert all(v <= tuple(map(int, _version(package).split('.'))) for v in released)
    assert sections[0] == 'Forthcoming' or sections[0].startswith(_version(package) + ' ')
