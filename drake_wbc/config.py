"""The controller's parameters from YAML (diagrams/controller.yaml).

`load_controller_parameters` reads a YAML file or string into
`ControllerParameters` with Drake's `yaml_load_typed`: the document's keys
are the dataclasses' fields, nested as in ControllerParameters, and a key
left out keeps its default (the paper's value), so a file may hold only
what it changes::

    time_step: 0.005
    distributor: {null_space_gain: 0.1}
    workspace: {mode: intuitive-phri}

`yaml_load_typed` builds the defaults and then assigns the fields it reads
one by one, without the dataclasses' checks; the loader therefore runs
every check of the whole tree afterwards (drake_wbc.validation.validate).
Every problem, from the YAML syntax to a value out of range, is raised as
a ValueError naming the file (if any), the field's dotted path (e.g.
`arm_cdmp.S_m`), the value and what is allowed.
"""

import dataclasses
import typing
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_dump, yaml_load_data, yaml_load_typed

from drake_wbc.controller import ControllerParameters
from drake_wbc.validation import validate

_LOADER_ERRORS = (yaml.YAMLError, RuntimeError, TypeError, ValueError,
                  AssertionError, AttributeError, NotImplementedError)
"""What yaml_load_typed raises on a document that does not fit the schema
(an unknown key, a list for a number, text for a number, ...)."""


def load_controller_parameters(path=None, text=None):
    """ControllerParameters from a YAML file or string, validated.

    Args:
        path: a YAML file (str or path-like); or
        text: YAML text. Give exactly one. An empty document (or one of
            comments only) gives the defaults.

    Returns:
        ControllerParameters.

    Raises:
        ValueError: naming the file (when loading one), the field's
            dotted path, its value and what is allowed; for an unknown
            key, the key's path and the keys allowed there.
        OSError: if the file cannot be read.
    """
    return load_typed(ControllerParameters, path=path, text=text)


def load_typed(schema, path=None, text=None):
    """An instance of the dataclass `schema` from a YAML file or string,
    with every check of its tree run (see load_controller_parameters).

    Args:
        schema: a parameters dataclass (ControllerParameters, a scenario,
            ...).
        path: a YAML file (str or path-like); or
        text: YAML text. Give exactly one.

    Returns:
        The loaded, validated instance of `schema`.

    Raises:
        ValueError: naming the file (when loading one), the field's
            dotted path, its value and what is allowed; for an unknown
            key, the key's path and the keys allowed there.
        OSError: if the file cannot be read.
    """
    if (path is None) == (text is None):
        raise ValueError(f"path = {path!r} and text = {text!r} are not "
                         "allowed: give exactly one of them")
    source = "" if path is None else f"{path}: "
    if path is not None:
        text = Path(path).read_text(encoding="utf-8")
    try:
        if yaml_load_data(text) is None:  # empty, or comments only
            text = "{}"
        params = yaml_load_typed(schema=schema, data=text)
    except _LOADER_ERRORS as error:
        raise ValueError(source + _explained(schema, text, error)) from None
    try:
        return validate(params)
    except ValueError as error:
        raise ValueError(f"{source}{error}") from None


def _explained(schema, text, error):
    """A message for `error` from yaml_load_typed on `text`, naming the key
    where it arose when one can be found."""
    if isinstance(error, yaml.YAMLError):
        return f"not valid YAML: {error}"
    document = yaml_load_data(text)
    found = None
    if isinstance(document, dict):
        found = _failing_key(document, schema, "")
    return found or str(error)


def _failing_key(document, schema, prefix):
    """The first key of the mapping `document` that the dataclass `schema`
    does not accept, described; None if each key loads on its own.

    Each entry is loaded alone, by yaml_load_typed itself, going down into
    nested parameters to the innermost key that fails."""
    hints = {item.name: item.type for item in dataclasses.fields(schema)}
    for key, value in document.items():
        name = f"{prefix}{key}"
        if key not in hints:
            where = f"in {prefix[:-1]}" if prefix else "at the top level"
            return (f"unknown key {name!r}; the keys allowed {where} are "
                    f"{', '.join(hints)}")
        nested = _dataclass_in(hints[key])
        if nested is not None and isinstance(value, dict):
            inner = _failing_key(value, nested, f"{name}.")
            if inner is not None:
                return inner
        item_schema = _list_item_dataclass(hints[key])
        if item_schema is not None and isinstance(value, list):
            for i, item in enumerate(value):
                if isinstance(item, dict):
                    inner = _failing_key(item, item_schema, f"{name}[{i}].")
                    if inner is not None:
                        return inner
        message = _load_error(schema, {key: value})
        if message is None:
            continue
        if nested is not None and not isinstance(value, dict):
            fields = ", ".join(item.name
                               for item in dataclasses.fields(nested))
            message = (f"must be a mapping of the fields of "
                       f"{nested.__name__} ({fields})")
        return f"{name} = {value!r} is not allowed: {message}"
    return None


def _load_error(schema, document):
    """The message of yaml_load_typed's error on `document`, or None."""
    try:
        yaml_load_typed(schema=schema, data=yaml_dump(document))
    except _LOADER_ERRORS as error:
        return str(error)
    return None


def _dataclass_in(hint):
    """The dataclass of a field's type hint (also inside `X | None`), or
    None."""
    for kind in (hint, *typing.get_args(hint)):
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            return kind
    return None


def _list_item_dataclass(hint):
    """The dataclass of the items of a `list[X]` type hint, or None."""
    if typing.get_origin(hint) is list:
        return _dataclass_in(typing.get_args(hint)[0])
    return None
