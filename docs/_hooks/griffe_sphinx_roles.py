"""griffe extension: turn the Sphinx roles of jaxnav's docstrings into mkdocstrings cross-references.

jaxnav's docstrings are Google style (parsed by mkdocstrings-python's ``google`` style) but name
other objects with Sphinx roles, e.g. ``:func:`kalman_filter``` or ``:class:`~jaxnav.io.ReaderError```.
mkdocstrings does not know these roles and would print them literally. This extension rewrites
each role, once the whole package is loaded, into an *optional* autorefs reference
``<autoref identifier="jaxnav.filters.kalman_filter" optional><code>kalman_filter</code></autoref>``:
a link when the target is documented on a page, plain code otherwise (optional references never
fail a strict build). Short names are resolved like Python would from the docstring's module
(its members and imports), then from the enclosing packages; ``~`` shows the last component only.

Many entries document several arguments on one line (``x0: (n,) initial mean.  P0: (n, n) ...``),
which the Google parser reads as one entry whose description swallows the others. Where the text
after a sentence's end and two spaces is ``name[, name]: `` and every name is a parameter (under
``Args:``) or a member (under ``Attributes:``) of the documented object, the line is split there
into its own entry; anything else stays as written.

Module-level constants documented by a ``#:`` comment above them or a trailing comment
(``DEG = math.pi / 180.0  # rad per degree``, the style of :mod:`jaxnav.units`) get that comment
as their docstring, and a class made by a call with its docstring as a string argument
(``KalmanResult = _record("KalmanResult", fields, doc)``, ``doc`` a string literal) gets that
string, so the pages show them.

The docstrings also document several arguments in one entry (``x, y: (N,) metres``), which the
Google parser does not split: mkdocs.yml turns its ``warn_unknown_params`` off, and this extension
does that check instead, name by name, so a misspelt or stale argument still fails the strict build.
"""

from __future__ import annotations

import ast
import html
import inspect
import re

import griffe

ROLE = re.compile(r":(?:py:)?(?P<role>func|class|mod|meth|attr|data|obj|exc|const):`(?P<body>[^`]+)`")


def _target(body: str) -> tuple[str, str]:
    """(shown text, dotted target) of a role body: ``~a.b`` -> ("b", "a.b"), ``text <a.b>`` -> ("text", "a.b")."""
    body = body.strip()
    m = re.fullmatch(r"(?P<text>.+?)\s*<(?P<target>[^>]+)>", body)
    if m:
        return m["text"], m["target"].lstrip("~.")
    target = body.lstrip("!")
    if target.startswith("~"):
        target = target[1:].lstrip(".")
        return target.rsplit(".", 1)[-1], target
    return target, target.lstrip(".")


def _resolve(obj: griffe.Object, target: str) -> str | None:
    """The path of ``target`` seen from ``obj``'s scope (its class, module, enclosing packages), or None."""
    if target.startswith("jaxnav"):
        return target
    head, _, rest = target.partition(".")
    scope = obj
    while scope is not None:
        try:
            member = scope.members.get(head) if hasattr(scope, "members") else None
        except Exception:  # an alias that cannot be resolved: try the next scope
            member = None
        if member is not None:
            try:
                path = member.target_path if member.is_alias else member.path
            except Exception:
                path = member.path
            return f"{path}.{rest}" if rest else path
        scope = scope.parent
    return None


def _rewrite(obj: griffe.Object, text: str) -> str:
    def sub(m: re.Match) -> str:
        shown, target = _target(m["body"])
        code = f"<code>{html.escape(shown)}</code>"
        path = _resolve(obj, target)
        if path is None:
            return code
        return f'<autoref identifier="{html.escape(path)}" optional>{code}</autoref>'

    return ROLE.sub(sub, text)


_SECTION = re.compile(r"^(?P<indent>\s*)(?P<title>Args|Arguments|Parameters|Attributes):\s*$")
_INLINE = re.compile(r"(?<=[.)])  +(?P<names>[A-Za-z_]\w*(?:, [A-Za-z_]\w*)*): ")


def _split_inline_entries(text: str, known: set[str], title_ok: tuple[str, ...]) -> str:
    """Put ``.  name: description`` runs of an Args/Attributes section on their own entry lines."""
    lines = text.split("\n")
    out, i = [], 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        m = _SECTION.match(line)
        i += 1
        if not m or m["title"] not in title_ok:
            continue
        base = len(m["indent"])
        entry_indent = None
        while i < len(lines) and (not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > base):
            cur = lines[i]
            i += 1
            ind = len(cur) - len(cur.lstrip())
            if cur.strip() and entry_indent is None:
                entry_indent = ind
            pieces, start = [], 0
            for mm in _INLINE.finditer(cur):
                names = [n.strip() for n in mm["names"].split(",")]
                if all(n in known for n in names):
                    pieces.append(cur[start : mm.start()].rstrip())
                    start = mm.start("names")
            if not pieces:
                out.append(cur)
                continue
            pieces.append(cur[start:])
            out.append(pieces[0])
            out += [" " * (entry_indent or ind) + piece.strip() for piece in pieces[1:]]
    return "\n".join(out)


def _check_params(func: griffe.Function) -> None:
    """Warn (as griffe would) for each name of an Args entry that is not a parameter of ``func``."""
    if func.docstring is None:
        return
    names = {p.name for p in func.parameters}
    variadic = any(
        p.kind in (griffe.ParameterKind.var_positional, griffe.ParameterKind.var_keyword) for p in func.parameters
    )
    sections = griffe.parse_google(func.docstring, warn_unknown_params=False, warnings=False)
    for section in sections:
        if section.kind is not griffe.DocstringSectionKind.parameters:
            continue
        for entry in section.value:
            for name in (n.strip().lstrip("*") for n in entry.name.split(",")):
                if name not in names and not variadic:
                    griffe.logger.warning(
                        f"{func.relative_filepath}:{func.docstring.lineno}: Parameter '{name}' of "
                        f"{func.path} (Args entry '{entry.name}') does not appear in the function signature"
                    )


_COMMENT = re.compile(r"#\s*(?P<text>.+?)\s*$")


def _new_docstring(attr: griffe.Attribute, text: str, lineno: int, endlineno: int) -> griffe.Docstring:
    """A docstring for ``attr`` parsed like the module's own (same parser and options)."""
    ref = attr.parent.docstring
    parser = ref.parser if ref is not None and ref.parser is not None else griffe.Parser.google
    options = dict(ref.parser_options) if ref is not None and ref.parser_options else {}
    return griffe.Docstring(
        text, lineno=lineno, endlineno=endlineno, parent=attr, parser=parser, parser_options=options
    )


def _runtime_fields(attr: griffe.Attribute) -> set[str]:
    """The ``_fields`` of the NamedTuple class a call built (importing the module), or an empty set."""
    try:
        import importlib

        cls = getattr(importlib.import_module(attr.parent.path), attr.name)
        return set(getattr(cls, "_fields", ()))
    except Exception:  # documentation only: without the fields nothing is split
        return set()


def _comment_docstring(attr: griffe.Attribute) -> None:
    """Document a module-level assignment from its source (see the module docstring)."""
    if attr.docstring is not None or not attr.parent or not attr.parent.is_module or attr.lineno is None:
        return
    try:
        lines = attr.parent.lines
        line = lines[attr.lineno - 1]
    except (IndexError, TypeError):
        return
    above, k = [], attr.lineno - 2
    while k >= 0 and lines[k].lstrip().startswith("#:"):
        above.insert(0, lines[k].lstrip()[2:].strip())
        k -= 1
    if above:
        attr.docstring = _new_docstring(attr, "\n".join(above), k + 2, attr.lineno - 1)
        return
    end = attr.endlineno or attr.lineno
    if end > attr.lineno:  # a multi-line value: a call that carries the docstring as a string argument
        try:
            node = ast.parse("\n".join(lines[attr.lineno - 1 : end])).body[0]
        except (SyntaxError, IndexError):
            return
        call = getattr(node, "value", None)
        if (
            isinstance(call, ast.Call)
            and call.args
            and isinstance(call.args[-1], ast.Constant)
            and isinstance(call.args[-1].value, str)
            and len(call.args) >= 2
        ):
            text = inspect.cleandoc(call.args[-1].value)
            fields = _runtime_fields(attr)
            if fields:
                text = _split_inline_entries(text, fields, ("Attributes",))
            attr.docstring = _new_docstring(attr, text, attr.lineno, end)
            attr.value = None  # the call holds the docstring itself: do not print it again as the value
        return
    m = _COMMENT.search(line.split("=", 1)[-1]) if "=" in line else None
    if m is None or "'" in line or '"' in line or m["text"].startswith(("noqa", "type:", "pragma")):
        return  # strings may hold a '#'; lint pragmas are not documentation
    attr.docstring = _new_docstring(attr, m["text"], attr.lineno, attr.lineno)


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles in every docstring of a loaded package (see the module docstring)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        seen: set[int] = set()

        def walk(obj):
            if id(obj) in seen or obj.is_alias:
                return
            seen.add(id(obj))
            if obj.is_attribute:
                _comment_docstring(obj)
            if obj.docstring is not None:
                obj.docstring.value = _rewrite(obj, obj.docstring.value)
                if obj.is_function:
                    known = {p.name for p in obj.parameters}
                    obj.docstring.value = _split_inline_entries(
                        obj.docstring.value, known, ("Args", "Arguments", "Parameters")
                    )
                elif obj.is_class:
                    known = set(obj.members) | {p.name for p in getattr(obj, "parameters", [])}
                    obj.docstring.value = _split_inline_entries(obj.docstring.value, known, ("Attributes",))
                if obj.is_function:
                    _check_params(obj)
            for member in list(obj.members.values()):
                if not member.is_alias:
                    walk(member)

        walk(pkg)
