# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""What a pipeline works out once per configuration and beam layout, not once per scan."""

from typing import Callable, Generic, Optional, Protocol, TypeVar

from .config import FeatureConfig


class Layout(Protocol):
    """What a prepared record was prepared for: a configuration and a beam layout."""

    @property
    def config(self) -> FeatureConfig:
        """Return the configuration."""

    @property
    def angle_increment_rad(self) -> float:
        """Return the layout's bearing step, rad."""

    @property
    def beam_count(self) -> int:
        """Return the layout's number of beams."""


Prepared = TypeVar('Prepared', bound=Layout)


class LatestPrepared(Generic[Prepared]):
    """
    The record prepared for the latest configuration and beam layout, prepared again on a change.

    A node or a bag replay extracts every scan with the same FeatureConfig object and layout:
    comparing them by identity costs well under a microsecond, where hashing the configuration
    (about 40 fields) for a cache costs several. One record, replaced whole, so that threads
    extracting at once each see a consistent one.
    """

    def __init__(self, prepare: Callable[[FeatureConfig, float, int], Prepared]) -> None:
        """
        Keep nothing yet.

        :param prepare: makes the record of (config, angle_increment_rad, beam_count)
        """
        self._prepare = prepare
        self.prepared: Optional[Prepared] = None

    def get(self, config: FeatureConfig, angle_increment_rad: float,
            beam_count: int) -> Prepared:
        """
        Return the record of a configuration and beam layout, prepared at most once in a row.

        :param config: the configuration
        :param angle_increment_rad: the scan's bearing step, rad
        :param beam_count: the scan's number of beams
        :return: the prepared record
        """
        prepared = self.prepared
        if (prepared is None or prepared.config is not config
                or prepared.angle_increment_rad != angle_increment_rad
                or prepared.beam_count != beam_count):
            prepared = self._prepare(config, angle_increment_rad, beam_count)
            self.prepared = prepared
        return prepared
