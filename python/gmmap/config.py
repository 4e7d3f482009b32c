"""The one configuration tree: YAML in, flags override it, the effective tree dumped beside results.

    build, select, register, place, backend, transport, link, robot, security, station, ros,
    planner, explore, sim

Each section is a dataclass of `gmmap.options`, where each setting has its one default.
``gmmap config --dump`` prints the defaults; every command takes ``--config FILE`` (a partial
tree: what it leaves out keeps its default) and its flags override single keys; every output
folder gets the effective ``config.yaml``.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import yaml

from gmmap.errors import InvalidInputError
from gmmap.options import (
    BackendOptions,
    BuildOptions,
    ExploreOptions,
    LinkOptions,
    PlaceOptions,
    PlannerOptions,
    RegisterOptions,
    RobotOptions,
    RosOptions,
    SecurityOptions,
    SelectOptions,
    SimOptions,
    StationOptions,
    TransportOptions,
)

FILE_NAME = "config.yaml"


class ConfigError(InvalidInputError):
    """A configuration file or override that does not fit the tree."""


@dataclass(frozen=True)
class Config:
    build: BuildOptions = field(default_factory=BuildOptions)
    select: SelectOptions = field(default_factory=SelectOptions)
    register: RegisterOptions = field(default_factory=RegisterOptions)
    place: PlaceOptions = field(default_factory=PlaceOptions)
    backend: BackendOptions = field(default_factory=BackendOptions)
    transport: TransportOptions = field(default_factory=TransportOptions)
    link: LinkOptions = field(default_factory=LinkOptions)
    robot: RobotOptions = field(default_factory=RobotOptions)
    security: SecurityOptions = field(default_factory=SecurityOptions)
    station: StationOptions = field(default_factory=StationOptions)
    ros: RosOptions = field(default_factory=RosOptions)
    planner: PlannerOptions = field(default_factory=PlannerOptions)
    explore: ExploreOptions = field(default_factory=ExploreOptions)
    sim: SimOptions = field(default_factory=SimOptions)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {f.name: _plain(dataclasses.asdict(getattr(self, f.name))) for f in fields(self)}

    def dump(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=False)

    @classmethod
    def from_dict(cls, tree: Mapping[str, Any] | None) -> Config:
        """A tree (sections of keys) over the defaults; unknown sections or keys are errors."""
        tree = tree or {}
        if not isinstance(tree, Mapping):
            raise ConfigError(
                f"a configuration is a mapping of sections, got {type(tree).__name__}"
            )
        known = {f.name: f for f in fields(cls)}
        unknown = sorted(set(tree) - set(known))
        if unknown:
            raise ConfigError(f"unknown section(s) {unknown}; sections: {', '.join(known)}")
        sections = {}
        for name, value in tree.items():
            default = known[name].default_factory()  # type: ignore[misc]
            sections[name] = _section(name, default, value or {})
        return cls(**sections)

    def override(self, values: Mapping[str, Any]) -> Config:
        """This tree with ``{"section.key": value}`` replaced; None values are skipped (a flag
        that was not given)."""
        tree = self.to_dict()
        for key, value in values.items():
            if value is None:
                continue
            section, _, name = key.partition(".")
            if section not in tree or name not in tree[section]:
                raise ConfigError(f"no setting {key!r}")
            tree[section][name] = _plain(value)
        return Config.from_dict(tree)

    def save(self, path: str | Path) -> Path:
        """Writes the tree as YAML to ``path`` (a folder: its ``config.yaml``)."""
        path = Path(path)
        if path.is_dir():
            path = path / FILE_NAME
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.dump())
        return path


def load_config(path: str | Path | None) -> Config:
    """The defaults overlaid with the YAML file at ``path`` (None: the defaults)."""
    if path is None:
        return Config()
    path = Path(path)
    try:
        tree = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such configuration file") from None
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not YAML: {err}") from None
    try:
        return Config.from_dict(tree)
    except (InvalidInputError, TypeError) as err:
        raise ConfigError(f"{path}: {err}") from None


def _section(name: str, default: Any, values: Any) -> Any:
    if not isinstance(values, Mapping):
        raise ConfigError(f"section {name!r} must be a mapping of keys, got {values!r}")
    hints = typing.get_type_hints(type(default))
    names = {f.name for f in fields(default)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"{name}: unknown key(s) {unknown}; keys: {', '.join(sorted(names))}")
    typed = {k: _coerce(f"{name}.{k}", hints[k], v) for k, v in values.items()}
    try:
        return dataclasses.replace(default, **typed)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{name}: {err}") from None


def _coerce(key: str, hint: Any, value: Any) -> Any:
    """``value`` as the annotated type: lists become tuples, ints become floats where floats are
    expected; anything else that does not fit is an error naming the key."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for option in (a for a in args if a is not type(None)):
            try:
                return _coerce(key, option, value)
            except ConfigError:
                continue
        raise ConfigError(f"{key}: {value!r} is not {hint}")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        item = args[0] if args else Any
        if (len(args) == 2 and args[1] is Ellipsis) or len(args) <= 1:
            return tuple(_coerce(key, item, v) for v in value)
        if len(args) != len(value):
            raise ConfigError(f"{key}: expected {len(args)} values, got {value!r}")
        return tuple(_coerce(key, a, v) for a, v in zip(args, value, strict=True))
    if origin is not None and issubclass(origin, Mapping):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key}: expected a mapping, got {value!r}")
        return dict(value)
    if hint is Any:
        return value
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if hint is bool or isinstance(value, bool):
        if not (hint is bool and isinstance(value, bool)):
            raise ConfigError(f"{key}: expected {hint.__name__}, got {value!r}")
        return value
    if isinstance(hint, type) and not isinstance(value, hint):
        raise ConfigError(f"{key}: expected {hint.__name__}, got {value!r}")
    return value


def _plain(value: Any) -> Any:
    """YAML-friendly: tuples as lists, mappings as dicts, all the way down."""
    if is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
