"""The config schema: plain config values checked against the typed settings that consume them.

Every config group is checked against its consumer before any work starts: a settings dataclass
(its fields, :func:`settings_from`) or a function or class (its keyword parameters,
:func:`check_arguments`). The annotations give the types; the consumers' own checks (a
settings class's ``__post_init__``, a constructor's) give the ranges. An unknown key, a value of
the wrong type or an out-of-range value raises :class:`ConfigError`, which names the dotted key,
the value and what is allowed. Plain Python only: entry points convert their Hydra config with
``OmegaConf.to_container`` first.
"""

from __future__ import annotations

import collections.abc
import difflib
import importlib
import inspect
import types
from collections.abc import Collection, Iterator, Mapping
from contextlib import contextmanager, suppress
from dataclasses import MISSING, fields
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

T = TypeVar("T")

#: Keys that ``hydra.utils.instantiate`` reads itself; they are no consumer's arguments.
INSTANTIATE_KEYS = frozenset({"_target_", "_convert_", "_recursive_", "_partial_", "_args_"})
_PLURALS = {bool: "booleans", int: "integers", float: "numbers", str: "strings"}
_NOUNS = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}


class ConfigError(ValueError):
    """A config entry that is not allowed.

    Attributes:
        key: Its dotted path, e.g. ``trainer.steps``.
        problem: What is wrong and what is allowed.
    """

    def __init__(self, key: str, problem: str) -> None:
        self.key, self.problem = key, problem
        super().__init__(f"Config entry {key}: {problem}" if key else problem)

    def under(self, group: str) -> ConfigError:
        """The same error with ``group`` prefixed to its key."""
        return ConfigError(join(group, self.key), self.problem)


def invalid(key: str, value: Any, allowed: str) -> ConfigError:
    """The error of a value that is not allowed: ``got <value>, expected <allowed>``."""
    return ConfigError(key, f"got {value!r}, expected {allowed}.")


def require(condition: bool, key: str, value: Any, allowed: str) -> None:
    """Raises :func:`invalid` unless ``condition`` holds."""
    if not condition:
        raise invalid(key, value, allowed)


def at_least(settings: Any, low: float, *names: str) -> None:
    """Checks that each attribute ``names`` of ``settings`` is at least ``low``."""
    for name in names:
        value = getattr(settings, name)
        kind = "an integer" if isinstance(value, int) else "a number"
        require(value >= low, name, value, f"{kind} of at least {low}")


def join(group: str, key: str) -> str:
    """The dotted key of ``key`` inside ``group``."""
    return f"{group}.{key}" if group and key else group or key


@contextmanager
def config_group(group: str) -> Iterator[None]:
    """Names ``group`` in the errors raised inside: a ``ConfigError``'s key gets it as prefix,
    and a consumer's own ``ValueError`` becomes a ``ConfigError`` of the group."""
    try:
        yield
    except ConfigError as err:
        raise err.under(group) from None
    except ValueError as err:
        raise ConfigError(group, str(err)) from err


def check_keys(values: Mapping[str, Any], allowed: Collection[str], group: str = "") -> None:
    """Raises a ``ConfigError`` for the first key of ``values`` that is not in ``allowed``."""
    for key, value in values.items():
        if key in allowed or key in INSTANTIATE_KEYS:
            continue
        close = difflib.get_close_matches(key, list(allowed), n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise ConfigError(
            join(group, key),
            f"unknown key (set to {value!r}){hint}; allowed keys: {', '.join(sorted(allowed))}.",
        )


def describe(annotation: Any) -> str:
    """What values an annotation admits, in words: ``an integer``, ``a list of numbers``."""
    origin, args = get_origin(annotation), get_args(annotation)
    if annotation is Any or annotation is inspect.Parameter.empty:
        return "any value"
    if annotation is None or annotation is type(None):
        return "null"
    if origin in (Union, types.UnionType):
        return " or ".join(describe(arg) for arg in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(arg) for arg in args)
    if annotation in _NOUNS:
        return _NOUNS[annotation]
    if origin in (tuple, list, collections.abc.Sequence):
        item = args[0] if args else Any
        return f"a list of {_PLURALS[item]}" if item in _PLURALS else "a list"
    if origin in (dict, collections.abc.Mapping) or annotation in (dict, Mapping):
        return "a mapping"
    return f"a {getattr(annotation, '__name__', annotation)}"


class _Mismatch(Exception):
    """A value that does not match an annotation (turned into a ConfigError by ``conform``)."""


def _conform(value: Any, annotation: Any) -> Any:
    origin, args = get_origin(annotation), get_args(annotation)
    if annotation is Any or annotation is inspect.Parameter.empty:
        return value
    if annotation is None or annotation is type(None):
        if value is None:
            return None
        raise _Mismatch
    if origin in (Union, types.UnionType):
        for arg in args:
            try:
                return _conform(value, arg)
            except _Mismatch:
                continue
        raise _Mismatch
    if origin is Literal:
        if any(value == arg and type(value) is type(arg) for arg in args):
            return value
        raise _Mismatch
    if annotation is bool or annotation is str:
        if isinstance(value, annotation):
            return value
        raise _Mismatch
    if annotation is int or annotation is float:
        numbers = (int, float) if annotation is float else (int,)  # an integer is a float too
        if isinstance(value, bool) or not isinstance(value, numbers):
            raise _Mismatch
        return annotation(value)
    if origin in (tuple, list, collections.abc.Sequence) or annotation in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise _Mismatch
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise _Mismatch
            return tuple(_conform(v, a) for v, a in zip(value, args, strict=True))
        items = [_conform(v, args[0] if args else Any) for v in value]
        return tuple(items) if tuple in (origin, annotation) else items
    if origin in (dict, collections.abc.Mapping) or annotation in (dict, Mapping):
        if not isinstance(value, Mapping):
            raise _Mismatch
        key_type, value_type = args or (Any, Any)
        return {_conform(k, key_type): _conform(v, value_type) for k, v in value.items()}
    if isinstance(annotation, type):
        if isinstance(value, annotation):
            return value
        raise _Mismatch
    return value  # a typing construct without a runtime check (e.g. a Callable or a TypeVar)


def conform(key: str, value: Any, annotation: Any) -> Any:
    """``value`` in the form ``annotation`` asks for (an integer as a float, a list as a tuple).

    Raises:
        ConfigError: The value does not match (e.g. a string for an integer).
    """
    try:
        return _conform(value, annotation)
    except _Mismatch:
        raise invalid(key, value, describe(annotation)) from None


def settings_from(cls: type[T], values: Mapping[str, Any], group: str = "") -> T:
    """A settings dataclass built from plain values, checked against its fields' annotations.

    The class's ``__post_init__`` checks the ranges; its errors name keys inside ``group``.
    """
    hints = get_type_hints(cls)
    init_fields = [f for f in fields(cls) if f.init]  # type: ignore[arg-type]
    check_keys(values, [f.name for f in init_fields], group)
    for f in init_fields:
        if f.name not in values and f.default is MISSING and f.default_factory is MISSING:
            raise ConfigError(join(group, f.name), "missing; this key is required.")
    kwargs = {k: conform(join(group, k), v, hints[k]) for k, v in values.items()}
    with config_group(group):
        return cls(**kwargs)


def _keyword_parameters(target: Any) -> tuple[dict[str, inspect.Parameter], dict[str, Any], bool]:
    """A callable's keyword parameters, their annotations, and whether it takes any keyword.

    A constructor ``__init__(self, ..., **kwargs)`` passes its keywords on to its base class's,
    whose parameters are followed.
    """
    inits = [target]
    if isinstance(target, type):
        inits = [k.__dict__["__init__"] for k in target.__mro__ if "__init__" in k.__dict__]
    params: dict[str, inspect.Parameter] = {}
    hints: dict[str, Any] = {}
    for init in inits:
        if init is object.__init__:
            break
        signature = inspect.signature(init)
        for name, param in signature.parameters.items():
            if name != "self" and param.kind in (param.POSITIONAL_OR_KEYWORD, param.KEYWORD_ONLY):
                params.setdefault(name, param)
        with suppress(NameError, TypeError):  # annotations that cannot be resolved go unchecked
            hints = {**get_type_hints(init), **hints}
        if not any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values()):
            return params, hints, False
    return params, hints, True


def parameter_annotation(target: Any, name: str) -> Any:
    """The resolved annotation of keyword parameter ``name`` of a function or class (or Any)."""
    return _keyword_parameters(target)[1].get(name, Any)


def check_arguments(
    target: Any, values: Mapping[str, Any], group: str = "", exclude: Collection[str] = ()
) -> dict[str, Any]:
    """Checks config values meant as keyword arguments of ``target`` (a function or class).

    Keys must name parameters of ``target`` (except ``exclude``, the ones code passes itself, and
    ``instantiate``'s own keys such as ``_target_``) and values must match their annotations.

    Returns:
        Every keyword argument of ``target`` except ``exclude``: the values, conformed, and the
        defaults of the others.
    """
    params, hints, open_keywords = _keyword_parameters(target)
    allowed = [name for name in params if name not in exclude]
    given = {k: v for k, v in values.items() if k not in INSTANTIATE_KEYS}
    if not open_keywords:
        check_keys(given, allowed, group)
    args = {k: conform(join(group, k), v, hints.get(k, Any)) for k, v in given.items()}
    for name in allowed:
        if name not in args:
            if params[name].default is inspect.Parameter.empty:
                raise ConfigError(join(group, name), "missing; this key is required.")
            args[name] = params[name].default
    return args


def target_arguments(
    values: Mapping[str, Any], group: str, exclude: Collection[str] = ()
) -> tuple[Any, dict[str, Any]]:
    """The class or function a config group's ``_target_`` names, and its keyword arguments
    from the group, checked by :func:`check_arguments`."""
    target = _locate(values, group)
    return target, check_arguments(target, values, group, exclude)


def _locate(values: Mapping[str, Any], group: str) -> Any:
    key = join(group, "_target_")
    target = values.get("_target_")
    example = "a dotted path to an importable class, e.g. kinet_rl.models.KINetWorldModel"
    if not isinstance(target, str) or "." not in target:
        raise invalid(key, target, example)
    module_name, _, name = target.rpartition(".")
    try:
        found = getattr(importlib.import_module(module_name), name)
    except (ImportError, AttributeError):
        raise invalid(key, target, example) from None
    require(callable(found), key, target, example)
    return found
