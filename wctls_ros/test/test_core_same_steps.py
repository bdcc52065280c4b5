# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The steps both cores have by the same name take the same arguments, so a rule reads alike.

The numpy core batches over segments or corners where the compiled one loops, but a step that
hands on records (Segments, Lines, Noise, the walls, CornerCandidates, the corner end rule's)
takes them by the same names in the same order in both, and a change to one reads the same in
the other. The steps listed are those that agree today; a step added to both belongs here. Not
yet: wall_at_corner, whose corners the numpy core takes batched as (x, y) rows.
"""

import inspect

import pytest
from wctls_ros.core.numpy_core import corners as numpy_corners
from wctls_ros.core.numpy_core import segmentation as numpy_segmentation

compiled_corners = pytest.importorskip('wctls_ros.core.numba_core.corners')
compiled_segmentation = pytest.importorskip('wctls_ros.core.numba_core.segmentation')

# (numpy module, compiled module, the steps of both that take the same arguments)
STEPS = [
    (numpy_segmentation, compiled_segmentation, ('pass_budget', 'trim_ambiguous', 'trim_offset')),
    (numpy_corners, compiled_corners, (
        'corner_candidates', 'corner_covariance', 'end_window', 'along_wall', 'corner_zone',
        'without_object_in_front', 'reaches', 'goes_on', 'blocked', 'short_of_corner',
        'dark_wall', 'seen_through', 'walls_end_at')),
]
SAME_ARGUMENTS = [(numpy_module, compiled_module, name)
                  for numpy_module, compiled_module, names in STEPS for name in names]


def arguments(function) -> list:
    """Return a function's argument names (a compiled kernel's: its Python function's)."""
    return list(inspect.signature(getattr(function, 'py_func', function)).parameters)


@pytest.mark.parametrize('numpy_module, compiled_module, name', SAME_ARGUMENTS,
                         ids=[name for _, _, name in SAME_ARGUMENTS])
def test_a_step_takes_the_same_arguments_in_both_cores(numpy_module, compiled_module, name):
    assert hasattr(numpy_module, name), f'the numpy core has no {name}'
    assert arguments(getattr(numpy_module, name)) == arguments(getattr(compiled_module, name))
