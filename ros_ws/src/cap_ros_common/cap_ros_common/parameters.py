"""Node parameters declared from a config dataclass: the dataclass is the one home of every default.

A node declares its parameters with `declare_config(node, MyConfig)`; the YAML files under config/ hold only
overrides. A field's description comes from `parameter(default, description)`; a nested dataclass field becomes
dotted names (`workspace.x_min`), which YAML writes as nested maps. Tuples are declared as ROS arrays and come
back as tuples. Fields whose type ROS parameters cannot carry (None defaults) are passed in `skip` and set by the
node itself. Only `declare_config` needs ROS (rcl_interfaces); `parameter()` and `parameter_names()` do not.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Iterable, TypeVar

Config = TypeVar('Config')


def parameter(default: Any, description: str, **field_options: Any) -> Any:
    """A dataclass field with a default and the description its ROS parameter is declared with."""
    if isinstance(default, (list, dict)):
        return dataclasses.field(default_factory=lambda: type(default)(default),
                                 metadata={'description': description}, **field_options)
    return dataclasses.field(default=default, metadata={'description': description}, **field_options)


def _default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    raise TypeError(f'config field {field.name!r} has no default')


def declare_config(node: Any, config_type: type[Config], *, prefix: str = '',
                   skip: Iterable[str] = ()) -> Config:
    """Declare one parameter per field of `config_type` on `node`; return the config with the values in force."""
    # Imported here: the config dataclasses that use `parameter()` live in plain modules that must not load ROS.
    from rcl_interfaces.msg import ParameterDescriptor

    skipped = set(skip)
    values: dict[str, Any] = {}
    for field in dataclasses.fields(config_type):
        if field.name in skipped or not field.init:
            continue
        default = _default(field)
        name = prefix + field.name
        if dataclasses.is_dataclass(default):
            values[field.name] = declare_config(node, type(default), prefix=name + '.',
                                                skip={s[len(field.name) + 1:] for s in skipped
                                                      if s.startswith(field.name + '.')})
            continue
        ros_default = list(default) if isinstance(default, tuple) else default
        descriptor = ParameterDescriptor(description=field.metadata.get('description', ''))
        value = node.declare_parameter(name, ros_default, descriptor).value
        values[field.name] = tuple(value) if isinstance(default, tuple) else value
    return config_type(**values)


def parameter_names(config_type: type, *, prefix: str = '') -> list[str]:
    """Every parameter name `declare_config` declares for `config_type` (nested fields dotted)."""
    names: list[str] = []
    for field in dataclasses.fields(config_type):
        if not field.init:
            continue
        default = _default(field)
        if dataclasses.is_dataclass(default):
            names += parameter_names(type(default), prefix=f'{prefix}{field.name}.')
        else:
            names.append(prefix + field.name)
    return names
