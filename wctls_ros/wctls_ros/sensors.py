# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Sensor presets: the noise model of a known 2D LiDAR, with the source of every number.

A preset is a YAML file ``config/sensors/<name>.yaml`` of the wctls_ros package::

    description: what the sensor is and where the numbers come from
    parameters: {range_sigma_m: ..., range_sigma_from_scan: ..., bearing_sigma_deg: ...,
                 common_range_sigma_m: ..., model_error_sigma_m: ...,
                 wall_flatness_sigma_m: ...}
    sources: {range_sigma_m: datasheet or our measurement, ...}

It sets exactly the :data:`PRESET_PARAMETERS` of feature_node (the parameter ``sensor`` picks
one; the values become those parameters' defaults, which a parameter file or a command line
still overrides). docs/sensors.md says how each was chosen. Pure Python: no rclpy import.
"""

from dataclasses import dataclass
import functools
import pathlib
from typing import Dict, Mapping, Union

from .plain_yaml import load_without_aliases

# The feature_node parameters a preset sets: the sensor's noise model.
PRESET_PARAMETERS = ('range_sigma_m', 'range_sigma_from_scan', 'bearing_sigma_deg',
                     'common_range_sigma_m', 'model_error_sigma_m', 'wall_flatness_sigma_m')
_FROM_SCAN = 'range_sigma_from_scan'
# The preset feature_node uses unless told otherwise (docs/sensors.md says why).
DEFAULT_SENSOR = 'generic'
PACKAGE = 'wctls_ros'


class PresetError(ValueError):
    """A preset file that does not say what a preset must say."""


@dataclass(frozen=True)
class SensorPreset:
    """
    One sensor's noise model.

    :ivar name: the preset's name (its file name without .yaml)
    :ivar description: what the sensor is and how far the numbers were checked
    :ivar parameters: feature_node parameter -> value, for every name of PRESET_PARAMETERS
        (range_sigma_from_scan a bool, the sigmas numbers)
    :ivar sources: parameter -> where its value comes from (datasheet, measurement)
    """

    name: str
    description: str
    parameters: Mapping[str, Union[float, bool]]
    sources: Mapping[str, str]

    @staticmethod
    def from_file(path: pathlib.Path) -> 'SensorPreset':
        """
        Read a preset file.

        :param path: ``<name>.yaml``
        :return: the preset
        :raises PresetError: when a parameter, or the source of one, is missing or unknown
        """
        document = load_without_aliases(path.read_text())
        if not isinstance(document, dict):
            raise PresetError(f'{path}: not a mapping')
        parameters, sources = document.get('parameters'), document.get('sources')
        if not isinstance(parameters, dict) or set(parameters) != set(PRESET_PARAMETERS):
            raise PresetError(f'{path}: parameters must set exactly {PRESET_PARAMETERS}')
        if not isinstance(sources, dict) or set(sources) != set(PRESET_PARAMETERS) or not all(
                isinstance(text, str) and text.strip() for text in sources.values()):
            raise PresetError(f'{path}: sources must give the source of each of '
                              f'{PRESET_PARAMETERS}')
        sigmas = [value for name, value in parameters.items() if name != _FROM_SCAN]
        if not all(isinstance(value, (int, float)) and not isinstance(value, bool)
                   and value >= 0 for value in sigmas):
            raise PresetError(f'{path}: the sigmas must be numbers >= 0')
        if not isinstance(parameters[_FROM_SCAN], bool):
            raise PresetError(f'{path}: {_FROM_SCAN} must be true or false')
        return SensorPreset(path.stem, str(document.get('description', '')).strip(),
                            {name: (parameters[name] if name == _FROM_SCAN
                                    else float(parameters[name])) for name in PRESET_PARAMETERS},
                            {name: sources[name].strip() for name in PRESET_PARAMETERS})


def preset_directory() -> pathlib.Path:
    """
    Return the folder of the preset files.

    In the source tree it is ``wctls_ros/config/sensors`` beside this package; installed, the
    package's share folder holds it (found through the ament index).

    :return: the folder
    """
    source = pathlib.Path(__file__).resolve().parents[1] / 'config' / 'sensors'
    if source.is_dir():
        return source
    from ament_index_python.packages import get_package_share_directory
    return pathlib.Path(get_package_share_directory(PACKAGE)) / 'config' / 'sensors'


@functools.lru_cache(maxsize=1)
def sensor_presets() -> Dict[str, SensorPreset]:
    """
    Return every shipped preset.

    :return: name -> preset, sorted by name
    :raises PresetError: on a preset file that is not valid, or none found (a broken install)
    """
    directory = preset_directory()
    presets = {path.stem: SensorPreset.from_file(path)
               for path in sorted(directory.glob('*.yaml'))}
    if DEFAULT_SENSOR not in presets:
        raise PresetError(f'no {DEFAULT_SENSOR}.yaml in {directory}: the package is not fully '
                          'installed')
    return presets
