# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""What the pipelines prepare once per configuration and beam layout."""

from typing import NamedTuple

from wctls_ros.core import FeatureConfig
from wctls_ros.core.prepared import LatestPrepared


class Layout(NamedTuple):
    """A prepared record: nothing but what it was prepared for."""

    config: FeatureConfig
    angle_increment_rad: float
    beam_count: int


def test_a_record_is_prepared_again_only_when_the_config_object_or_the_layout_changes():
    made = []

    def prepare(*layout):
        made.append(layout)
        return Layout(*layout)

    latest = LatestPrepared(prepare)
    config, equal = FeatureConfig(), FeatureConfig()
    first = latest.get(config, 0.01, 360)
    assert latest.get(config, 0.01, 360) is first and len(made) == 1
    assert latest.get(config, 0.02, 360) is not first and len(made) == 2
    assert latest.get(config, 0.02, 720).beam_count == 720 and len(made) == 3
    assert latest.get(equal, 0.02, 720).config is equal and len(made) == 4
