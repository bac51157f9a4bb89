"""YAML configuration files of the experiments, read with the line of every key, so that a bad entry is
one error naming the file, the line and the key."""

from __future__ import annotations

from pathlib import Path

import yaml

from cpg_walker.errors import InputError
from cpg_walker.paths import yaml_error


class ConfigError(InputError):
    """A bad configuration entry (the message names file, line and key)."""


class Config:
    """A parsed YAML mapping and the line (1-based) of each key path."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        text = self.path.read_text(encoding="utf-8")
        try:
            node = yaml.compose(text)
            self.data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ConfigError(yaml_error(self.path, exc)) from None
        if not isinstance(self.data, dict):
            raise ConfigError(f"{self.path}: expected a mapping at the top level")
        self.lines: dict[tuple, int] = {}
        self._walk(node, ())

    def _walk(self, node, prefix: tuple) -> None:
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                key = (*prefix, k.value)
                self.lines[key] = k.start_mark.line + 1
                self._walk(v, key)
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                self.lines[(*prefix, i)] = v.start_mark.line + 1
                self._walk(v, (*prefix, i))

    def where(self, *key) -> str:
        """'FILE:LINE key.path' of a key (the nearest known parent's line)."""
        k = tuple(key)
        while k and k not in self.lines:
            k = k[:-1]
        line = self.lines.get(k)
        name = ".".join(str(x) for x in key)
        return f"{self.path}:{line} {name}" if line else f"{self.path} {name}"

    def error(self, key: tuple, problem: str) -> ConfigError:
        return ConfigError(f"{self.where(*key)}: {problem}")

    def check_known(self, data: dict, template: dict, prefix: tuple = ()) -> None:
        """Every key of ``data`` (nested mappings too) must be a key of ``template``."""
        for k, v in data.items():
            if k not in template:
                raise self.error((*prefix, k), f"unknown key; known: {', '.join(map(str, template))}")
            if isinstance(v, dict) and isinstance(template[k], dict):
                self.check_known(v, template[k], (*prefix, k))


def deep_merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` merged in (nested mappings merged, everything else replaced)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out
