# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
YAML files a user or a bag hands us, read without aliases.

A YAML alias (``*name``) repeats a node without copying its text, so nested aliases make a file
of a few hundred bytes stand for billions of values: anything that walks or prints the result
(a check, an error message quoting a value) allocates gigabytes. Our files (floor plans,
parameter files, truth and label files) never need aliases, and ROS 2's parameter-file parser
does not accept them either. Pure Python: no rclpy import.
"""

import yaml


class _AliasFreeLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses an alias where it would compose the aliased node again."""

    def compose_node(self, parent, index):
        """Compose the next node; an alias is a ComposerError that says where it is."""
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise yaml.composer.ComposerError(
                None, None, f'an alias (*name) at line {mark.line + 1}, column {mark.column + 1}:'
                ' YAML aliases are not accepted, write the values out')
        return super().compose_node(parent, index)


def load_without_aliases(text: str):
    """
    Parse YAML text like yaml.safe_load, refusing aliases.

    :param text: the YAML document
    :return: the parsed document (dicts, lists, scalars)
    :raises yaml.YAMLError: on invalid YAML or an alias (the first line says where)
    """
    return yaml.load(text, Loader=_AliasFreeLoader)
