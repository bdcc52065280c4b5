# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Check docstrings with ament_pep257's 'ament' convention (reST fields, no Google sections)."""

import pytest

from test_flake8 import LINTED


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    main = pytest.importorskip('ament_pep257.main').main
    assert main(argv=LINTED) == 0, 'Found code style errors / warnings'
