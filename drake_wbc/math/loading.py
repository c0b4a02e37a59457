"""Loading parameter dataclasses from YAML, safe against hostile files.

`load_typed(schema, path=..., text=...)` reads a YAML document into the
dataclass `schema` (ControllerParameters, a Scenario, ...) with Drake's
`yaml_load_typed` and then runs every check of the tree
(drake_wbc.math.validation.validate). A key left out keeps its default.

Before Drake sees the document, it is screened as a stream of YAML events
(`screen`: a parser that needs no recursion), so that a file written to
hurt the loader is refused in milliseconds, with a message, instead of
burning CPU and memory or ending in a traceback from deep in yaml:

- the file holds at most MAX_BYTES bytes of UTF-8 text (a byte that is not
  UTF-8 is reported with its line and column);
- lists and mappings nest at most MAX_DEPTH deep (the deepest field of a
  scenario is 7 levels down);
- at most MAX_ALIASES aliases (`*name`), each to an anchor (`&name`)
  defined before it and outside the node that holds the alias (no cycle),
  and the document expanded (every alias replaced by its anchor's node)
  has at most MAX_NODES nodes: a "billion laughs" is refused, never
  expanded, and no error message shows more than a short rendering of a
  value;
- no mapping repeats a key (YAML forbids it; PyYAML and Drake would keep
  the last one silently). The merge key `<<` may override what it merges.

Every problem, from the YAML syntax to a value out of range, is raised as
a ValueError naming the file (if any), the field's dotted path (e.g.
`arm_cdmp.S_m`), the value (shortened) and what is allowed.
"""

import dataclasses
import types
import typing
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_dump, yaml_load_data, yaml_load_typed

from drake_wbc.math.validation import validate

MAX_BYTES = 1024 * 1024
"""The largest file the loader reads, bytes (the scenarios of diagrams/
hold 2 to 7 KB)."""

MAX_DEPTH = 32
"""The deepest nesting of lists and mappings allowed (a scenario's
deepest field, a learned movement's goal in a variant, is 7 deep)."""

MAX_ALIASES = 100
"""The most aliases (`*name`) a document may use: enough to share a few
settings between the fields of a scenario (YAML's anchors and merge keys,
which Drake's loader understands), far too few to multiply a node."""

MAX_NODES = 50_000
"""The most nodes (scalars, lists and mappings) of a document once every
alias is replaced by its anchor's node, as PyYAML and Drake expand them:
a schedule of 6,000 six-vectors, loaded in about 10 s (the scenarios of
diagrams/ hold at most 600)."""

SHORT = 60
"""The longest rendering of a value in an error message, characters."""

LOADER_ERRORS = (yaml.YAMLError, ArithmeticError, AssertionError,
                 AttributeError, LookupError, NotImplementedError,
                 RuntimeError, TypeError, ValueError)
"""What yaml_load_typed (and the dataclasses' checks, on values of an
unexpected type) raise on a document that does not fit the schema: an
unknown key, a list for a number, text for a number, a mapping for a
list, ..."""


def load_typed(schema, path=None, text=None):
    """An instance of the dataclass `schema` from a YAML file or string,
    with every check of its tree run.

    Args:
        schema: a parameters dataclass (ControllerParameters, a scenario,
            ...).
        path: a YAML file (str or path-like); or
        text: YAML text. Give exactly one. An empty document (or one of
            comments only) gives the defaults.

    Returns:
        The loaded, validated instance of `schema`.

    Raises:
        ValueError: naming the file (when loading one), the field's
            dotted path, its value and what is allowed; for an unknown
            key, the key's path and the keys allowed there; for a
            document that could hurt the loader (see the module's
            docstring), the line and what is allowed.
        OSError: if the file cannot be read.
    """
    if (path is None) == (text is None):
        raise ValueError(f"path = {short_value(path)} and text = "
                         f"{short_value(text)} are not allowed: give exactly "
                         "one of them")
    source = "" if path is None else f"{path}: "
    try:
        if path is not None:
            text = _read_text(path)
        elif not isinstance(text, str):
            raise ValueError(f"text = {short_value(text)} is not allowed: must "
                             "be a string of YAML")
        elif len(text.encode("utf-8", "surrogatepass")) > MAX_BYTES:
            raise ValueError(
                f"text of {len(text)} characters is not allowed: at most "
                f"{MAX_BYTES} bytes of YAML")
        screen(text)
        document = yaml_load_data(text)
        if document is None:  # empty, or comments only
            document, text = {}, "{}"
        if not isinstance(document, dict):
            raise ValueError(
                f"the document = {short_value(document)} is not allowed: "
                f"must be a mapping of the fields of {schema.__name__} "
                f"({_field_names(schema)})")
        try:
            params = yaml_load_typed(schema=schema, data=text)
        except LOADER_ERRORS as error:
            raise ValueError(_explained(schema, document, error)) from None
        try:
            return validate(params)
        except LOADER_ERRORS as error:
            raise ValueError(shortened(str(error))) from None
    except ValueError as error:
        raise ValueError(f"{source}{error}") from None
    except yaml.YAMLError as error:
        raise ValueError(f"{source}not valid YAML: {error}") from None


def screened_data(path=None, text=None):
    """The plain data (mappings, lists, scalars) of the YAML file `path`
    or of the YAML `text`, read as `load_typed` reads one: at most
    MAX_BYTES bytes of UTF-8, `screen`ed before PyYAML's safe loader
    builds it; for a file that is not a parameters dataclass (a learned
    movement, drake_wbc.math.movement), or to see which keys a document
    gives.

    Raises:
        ValueError: for a file too large, not UTF-8, or that could hurt
            the loader (the module's docstring), with the line and what
            is allowed; or unless exactly one of path and text is given.
        yaml.YAMLError: for text that is not YAML.
        OSError: if the file cannot be read.
    """
    if (path is None) == (text is None):
        raise ValueError(f"path = {short_value(path)} and text = "
                         f"{short_value(text)} are not allowed: give exactly "
                         "one of them")
    text = _read_text(path) if path is not None else text
    screen(text)
    return yaml.safe_load(text)


def _read_text(path):
    """The text of the file `path`: at most MAX_BYTES bytes of UTF-8."""
    with Path(path).open("rb") as stream:
        data = stream.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:
        raise ValueError(f"a file of more than {MAX_BYTES} bytes is not "
                         f"allowed: at most {MAX_BYTES} bytes of YAML")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        before = data[:error.start]
        line = before.count(b"\n") + 1
        column = error.start - (before.rfind(b"\n") + 1) + 1
        raise ValueError(
            f"line {line}, column {column}: byte 0x{data[error.start]:02x} is "
            "not allowed: the file must be UTF-8 text (save it as UTF-8)"
        ) from None


_EVENTS = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""The parser of `screen`: LibYAML's when PyYAML has it (ten times as
fast), else PyYAML's own; both emit the same events."""


class _Node:
    """A list or mapping being read: its dotted path, its expanded size
    (itself and everything inside), and, for a mapping, its keys so far."""

    def __init__(self, event, path):
        self.path, self.anchor, self.size = path, event.anchor, 1
        self.mapping = isinstance(event, yaml.MappingStartEvent)
        self.keys, self.key, self.items = {}, None, 0
        self.expecting_key = self.mapping

    def child_path(self):
        if self.mapping:
            name = "?" if self.key is None else str(self.key)
            return f"{self.path}.{name}" if self.path else name
        return f"{self.path}[{self.items}]"


def screen(text):
    """Checks the YAML `text` against what could hurt the loader, as a
    stream of events, before anything builds it (see the module's
    docstring): nesting depth, aliases, expanded size, duplicate keys.

    Returns:
        The number of nodes (scalars, lists and mappings) of the document
        with every alias replaced by its anchor's node.

    Raises:
        ValueError: naming the line and column, the field's dotted path,
            what was found and what is allowed.
        yaml.YAMLError: for text that is not YAML (from PyYAML's parser,
            with its line and column).
    """
    stack, sizes, aliases, total = [], {}, 0, 0

    def fail(event, path, found, allowed):
        mark = event.start_mark
        field = f"{path} = " if path else ""
        raise ValueError(f"line {mark.line + 1}, column {mark.column + 1}: "
                         f"{field}{found} is not allowed: {allowed}")

    def count(event, size):
        nonlocal total
        total += size
        if total > MAX_NODES:
            found = (f"*{event.anchor}" if isinstance(event, yaml.AliasEvent)
                     else "the next value")
            fail(event, path_here(), f"{found}, which takes the document "
                 f"beyond {MAX_NODES} values (aliases expanded),",
                 f"a document holds at most {MAX_NODES} scalars, lists and "
                 "mappings")

    def done(event, size):
        """A node of expanded `size` ended: account for it in its parent."""
        if not stack:
            return
        parent = stack[-1]
        parent.size += size
        if not parent.mapping:
            parent.items += 1
        elif parent.expecting_key:
            key = (event.value if isinstance(event, yaml.ScalarEvent)
                   else None)
            if key is not None and key != "<<":
                first = parent.keys.get(key)
                if first is not None:
                    name = f"{parent.path}.{key}" if parent.path else key
                    fail(event, "", f"key {name!r} again (first at line "
                         f"{first})", "a key may appear only once in a "
                         "mapping")
                parent.keys[key] = event.start_mark.line + 1
            parent.key, parent.expecting_key = key, False
        else:
            parent.expecting_key = True

    def path_here():
        path = stack[-1].child_path() if stack else ""
        return path if len(path) <= SHORT else (
            f"{path[:SHORT - 20]}...{path[-12:]}")

    for event in yaml.parse(text, Loader=_EVENTS):
        if isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_ALIASES:
                fail(event, path_here(), f"alias *{event.anchor}",
                     f"a document may use at most {MAX_ALIASES} aliases")
            if any(node.anchor == event.anchor for node in stack):
                fail(event, path_here(), f"alias *{event.anchor}",
                     f"an alias may not refer to a node that holds it (&"
                     f"{event.anchor} would contain itself)")
            if event.anchor not in sizes:
                fail(event, path_here(), f"alias *{event.anchor}",
                     "an alias must refer to an anchor (&name) defined "
                     "before it")
            size = sizes[event.anchor]
        elif isinstance(event, yaml.ScalarEvent):
            size = 1
        elif isinstance(event, yaml.CollectionStartEvent):
            if len(stack) >= MAX_DEPTH:
                opening = ("{" if isinstance(event, yaml.MappingStartEvent)
                           else "[")
                fail(event, path_here(), f"{opening * 3}... nested deeper "
                     f"than {MAX_DEPTH} levels",
                     f"lists and mappings nest at most {MAX_DEPTH} deep")
            count(event, 1)
            stack.append(_Node(event, path_here()))
            continue
        elif isinstance(event, yaml.CollectionEndEvent):
            node = stack.pop()
            if node.anchor is not None:
                sizes[node.anchor] = node.size
            done(event, node.size)
            continue
        else:
            continue
        if isinstance(event, yaml.ScalarEvent) and event.anchor is not None:
            sizes[event.anchor] = size
        count(event, size)
        done(event, size)
    return total


def shortened(message):
    """`message` with the value it shows (between the first ` = ` and the
    following ` is not allowed`) cut to about SHORT characters."""
    end = message.find(" is not allowed")
    start = message.rfind(" = ", 0, end) + 3 if end > 0 else -1
    if start < 3 or end - start <= SHORT:
        return message
    value = message[start:end]
    return (f"{message[:start]}{value[:SHORT - 20]} ... {value[-12:]} "
            f"({len(value)} characters){message[end:]}")


def short_value(value, limit=SHORT):
    """A rendering of `value` (plain data from YAML) of at most about
    `limit` characters, built without rendering what is cut (a shared
    structure is never expanded)."""
    parts, budget = [], [limit]

    def add(text):
        parts.append(text[:max(budget[0], 0)])
        budget[0] -= len(text)
        return budget[0] > 0

    def walk(item):
        if isinstance(item, dict):
            if not add("{"):
                return False
            for i, (key, inner) in enumerate(item.items()):
                if (i and not add(", ")) or not add(f"{key}: ") or not walk(
                        inner):
                    return False
            return add("}")
        if isinstance(item, (list, tuple)):
            if not add("["):
                return False
            for i, inner in enumerate(item):
                if (i and not add(", ")) or not walk(inner):
                    return False
            return add("]")
        return add(repr(item))

    if not walk(value):
        parts.append(" ...")
    return "".join(parts)


def _field_names(schema):
    return ", ".join(item.name for item in dataclasses.fields(schema))


def _explained(schema, document, error):
    """A message for `error` from yaml_load_typed on `document` (a dict),
    naming the key where it arose when one can be found."""
    return _failing_key(document, schema, "") or shortened(str(error))


def _failing_key(document, schema, prefix):
    """The first key of the mapping `document` that the dataclass `schema`
    does not accept, described; None if each key loads on its own.

    Each entry is loaded alone, by yaml_load_typed itself, going down into
    nested parameters (and the items of lists of them) to the innermost
    key that fails."""
    hints = {item.name: item.type for item in dataclasses.fields(schema)}
    for key, value in document.items():
        name = f"{prefix}{key}"
        if key not in hints:
            where = f"in {prefix[:-1]}" if prefix else "at the top level"
            return (f"unknown key {short_value(name)}; the keys allowed "
                    f"{where} are {', '.join(hints)}")
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
        if item_schema is not None and not isinstance(value, list):
            message = (f"must be a list of {item_schema.__name__} (each a "
                       f"mapping of {_field_names(item_schema)})")
        elif _allowed(hints[key]) is not None:
            message = _allowed(hints[key])
        elif typing.get_origin(hints[key]) is list and not isinstance(
                value, list):
            message = "must be a list"
        elif nested is not None and not isinstance(value, dict):
            message = (f"must be a mapping of the fields of "
                       f"{nested.__name__} ({_field_names(nested)})")
        return f"{name} = {short_value(value)} is not allowed: {message}"
    return None


_KINDS = {float: "a number", int: "a whole number", bool: "true or false",
          str: "a string"}
"""What a field of each plain type holds, said in an error."""

_KINDS_OF_ITEMS = {float: "numbers", int: "whole numbers",
                   bool: "booleans (true or false)", str: "strings"}


def _allowed(hint):
    """What a field of type `hint` allows, as `must be ...`, for the plain
    types and lists of them (also `X | None`: or null); None for others,
    whose loader's message stands (yaml_load_typed says, e.g., "could not
    convert string to float" of a number field)."""
    kinds = typing.get_args(hint) if isinstance(
        hint, types.UnionType) else (hint,)
    optional = type(None) in kinds
    kinds = [kind for kind in kinds if kind is not type(None)]
    if len(kinds) != 1:
        return None
    kind, = kinds
    if kind in _KINDS:
        wanted = _KINDS[kind]
    elif (typing.get_origin(kind) is list
          and typing.get_args(kind)[0] in _KINDS_OF_ITEMS):
        wanted = f"a list of {_KINDS_OF_ITEMS[typing.get_args(kind)[0]]}"
    else:
        return None
    return f"must be {wanted}" + (" or null" if optional else "")


def _load_error(schema, document):
    """The message of yaml_load_typed's error on `document`, or None."""
    try:
        yaml_load_typed(schema=schema, data=yaml_dump(document))
    except LOADER_ERRORS as error:
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
