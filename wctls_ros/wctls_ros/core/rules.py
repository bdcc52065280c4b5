# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The constants of the pipeline's rules, shared by its two implementations.

Neither core imports the other: the numpy core (:mod:`.numpy_core`) and its compiled twin
(:mod:`.numba_core`) both read their rules' numbers here, so the compiled kernels' cache depends on
this module and not on the numpy core's source. The rules themselves are stated in
docs/derivation.md and in the numpy core's docstrings.
"""

import math

# #range-noise-from-the-scan: fewer triples of neighbouring returns than this estimate nothing
# (a scan of a few returns).
MIN_TRIPLES = 30
# 1 / Phi^-1(3/4): the median absolute deviation of a normal sample times this is its sigma.
MAD_TO_SIGMA = 1.482602218505602
# Second differences beyond this many sigma are not noise (edges, mixed pixels, clutter)...
CUT_SIGMAS = 3.0
# ... and a normal sample cut there keeps this share of its variance: 1 - 2 k phi(k) / (2 Phi(k)
# - 1) for k = 3.
CUT_VARIANCE = 1.0 - 2.0 * CUT_SIGMAS * math.exp(-0.5 * CUT_SIGMAS ** 2) / math.sqrt(
    2.0 * math.pi) / math.erf(CUT_SIGMAS / math.sqrt(2.0))
# Re-cuts after the median absolute deviation's first guess (the sigma settles in two).
REFINEMENTS = 3

# #segmentation-statistics: a chord shorter than this (m) has no usable direction: distances are
# measured from its start.
MIN_CHORD_M = 1e-9
# A segment needs this many returns to be fitted (and so to take part in merging).
MIN_FIT_RETURNS = 3
# The work bound of IEPF and merging: passes per scan of n returns, 2 ceil(log2 n) + 8 (see
# :func:`.numpy_core.segmentation.pass_budget`).
BUDGET_LEVELS_PER_DOUBLING = 2
BUDGET_EXTRA_PASSES = 8
# A break between two returns one surface could have given is one the noise made: their
# distance exceeds the surface's allowance by at most this many sigma of the difference of two
# returns (a pair on one surface goes beyond it with probability 6e-7). Beyond it, the break is
# a discontinuity, which merging never crosses.
JOINABLE_SIGMAS = 5.0 * math.sqrt(2.0)

# #maximum-likelihood: Gauss-Newton stops once every step is below this (rad and m)...
ML_STEP_TOLERANCE = 1e-12
# ... or after this many iterations. From the WTLS line it takes 5 to 8 on simulated S1 scans
# (the variances move with the line, so convergence is linear), the last step below 1e-12.
ML_MAX_ITERATIONS = 8

# #corners: a corner may sit one beam without a return beyond a wall's last return (a dropout
# there), reported with that wall's end not seen; farther, it is an extrapolation, not a corner.
CORNER_MISSING_BEAMS = 1
# #corners, "Dark wall": beams without a return (outside the scan's range_min and range_max,
# inf, NaN) where a wall would have to reach the corner tell an opening when they run over more
# than 1 + CORNER_MISSING_BEAMS beams and leave more than this much (m) of the walls' extension
# unseen; a LiDAR sees a wall a few metres away, and a dropout on a dark or glossy spot of a real
# wall leaves a few centimetres (at most 0.1 m at the labelled corners of data/labels). Tuned on
# data/urg04lx_office alone, whose false corner leaves 0.41-0.87 m dark and whose true ones none.
CORNER_DARK_WALL_M = 0.2

# #landmark-tracks: a track's state by code, in the tracker (wctls_ros.frontend.tracking) and its
# compiled kernels (numba_core/tracking.py): new, seen often enough, missed too often in view.
TENTATIVE = 0
CONFIRMED = 1
LOST = 2
