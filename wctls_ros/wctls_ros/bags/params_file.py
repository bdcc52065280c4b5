# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
feature_node's parameters from a ROS 2 parameter file, checked as the node checks them.

Offline tools take the same YAML file as ``feature_node --ros-args --params-file``: the
``feature_node`` (or ``/**``) section's ``ros__parameters`` are checked against the node's
parameter specs (names, types, ranges) and then built into the pipeline configuration by
:func:`wctls_ros.feature_node.settings_from_parameters`, so a file is accepted offline exactly
when the node would accept it.
"""

import pathlib
from typing import Optional

import yaml

from ..feature_node import PARAMETERS

# Parameters every node has (or that rclpy adds) which the offline tools ignore.
_IGNORED = ('use_sim_time',)
_IGNORED_PREFIXES = ('qos_overrides.',)


class ConfigError(ValueError):
    """A parameter file that feature_node would refuse, with the reason."""


def _flatten(parameters: dict, prefix: str = '') -> dict:
    """Turn nested parameter mappings into dotted names, as rcl does for parameter files."""
    flat = {}
    for name, value in parameters.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f'{prefix}{name}.'))
        else:
            flat[f'{prefix}{name}'] = value
    return flat


def _sections(document: dict, node_name: str) -> list:
    """Return the ros__parameters mappings that apply to the node, wildcards first."""
    wildcards, own = [], []
    for key, section in document.items():
        key = str(key)
        name = key.rstrip('/').rsplit('/', 1)[-1]
        if key in ('/**', '**'):
            target = wildcards
        elif name == node_name:
            target = own
        else:
            continue
        if not isinstance(section, dict) or not isinstance(section.get('ros__parameters'), dict):
            raise ConfigError(f'section {key!r} has no ros__parameters mapping')
        target.append(section['ros__parameters'])
    return wildcards + own


def _checked(spec, value):
    """Return the value as the parameter's type, or raise ConfigError like rclpy refuses it."""
    default = spec.default
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(f'{spec.name} must be of type {type(default).__name__}, got '
                          f'{value!r}')
    if spec.limits is not None and not isinstance(default, bool):
        low, high = spec.limits
        if not low <= value <= high:
            raise ConfigError(f'{spec.name} = {value!r} is outside its range [{low}, {high}]')
    return value


def load_parameters(path, node_name: str = 'feature_node',
                    overrides: Optional[dict] = None) -> dict:
    """
    Read feature_node's parameter values from a parameter file, over the defaults.

    :param path: a ROS 2 YAML parameter file (None: defaults only)
    :param node_name: the section to read besides ``/**``
    :param overrides: values applied after the file (e.g. from the command line)
    :return: parameter name -> value, for every name in feature_node's PARAMETERS
    :raises ConfigError: for an unreadable file, an unknown name, a wrong type or range
    """
    specs = {spec.name: spec for spec in PARAMETERS}
    given = {}
    if path is not None:
        path = pathlib.Path(path)
        try:
            document = yaml.safe_load(path.read_text())
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
            raise ConfigError(f'cannot read the parameter file {path}: '
                              f'{str(error).splitlines()[0]}') from error
        if not isinstance(document, dict):
            raise ConfigError(f'{path} is not a ROS 2 parameter file (a mapping of node names)')
        sections = _sections(document, node_name)
        if not sections:
            raise ConfigError(f'{path} has no parameters for {node_name} (expected a '
                              f"'{node_name}:' or '/**:' section with ros__parameters)")
        for section in sections:
            given.update(_flatten(section))
    given.update(overrides or {})
    unknown = sorted(name for name in given if name not in specs and name not in _IGNORED
                     and not name.startswith(_IGNORED_PREFIXES))
    if unknown:
        raise ConfigError(f'unknown {node_name} parameters {unknown}; known: {sorted(specs)}')
    values = {name: spec.default for name, spec in specs.items()}
    values.update({name: _checked(specs[name], value) for name, value in given.items()
                   if name in specs})
    return values
