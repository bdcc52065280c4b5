# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
YAML files a user or a bag hands us, read without aliases.

A YAML alias (``*name``) repeats a node without copying its text, so nested aliases make a file
of a few hundred bytes stand for billions of values: anything that walks or prints the result
(a check, an error message quoting a value) allocates gigabytes. Our files (floor plans,
parameter files, truth and label files) never need aliases, and ROS 2's parameter-file parser
does not accept them either. Nor do they nest more than a few levels, while PyYAML composes a
nested node by recursion: a file nested thousands of levels deep (``[[[[...``) would end in a
RecursionError and a traceback thousands of lines long, so nesting is limited too. Pure Python:
no rclpy import.
"""

import yaml

# Collections nested deeper than this are refused; ours nest at most 4 levels (a floor plan's
# polyline points), and PyYAML's recursion reaches Python's limit at about 300.
MAX_NESTING = 50


class _PlainLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses aliases, and collections nested deeper than MAX_NESTING."""

    def __init__(self, stream):
        super().__init__(stream)
        self._nesting = 0

    def _refuse(self, what: str, advice: str):
        mark = self.peek_event().start_mark
        raise yaml.composer.ComposerError(
            None, None, f'{what} at line {mark.line + 1}, column {mark.column + 1}: {advice}')

    def compose_node(self, parent, index):
        """Compose the next node; an alias or a deep nesting is a ComposerError saying where."""
        if self.check_event(yaml.AliasEvent):
            self._refuse('an alias (*name)', 'YAML aliases are not accepted, write the values out')
        collection = self.check_event(yaml.SequenceStartEvent, yaml.MappingStartEvent)
        if collection and self._nesting >= MAX_NESTING:
            self._refuse(f'collections nested more than {MAX_NESTING} deep',
                         'our files nest a few levels at most')
        self._nesting += collection
        try:
            return super().compose_node(parent, index)
        finally:
            self._nesting -= collection


def load_without_aliases(text: str):
    """
    Parse YAML text like yaml.safe_load, refusing aliases and deep nesting.

    :param text: the YAML document
    :return: the parsed document (dicts, lists, scalars)
    :raises yaml.YAMLError: on invalid YAML, an alias or collections nested more than
        MAX_NESTING deep (the first line says where)
    """
    return yaml.load(text, Loader=_PlainLoader)
