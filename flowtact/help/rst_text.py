"""reStructuredText docstrings as plain terminal text, for ``flowtact blocks NAME`` (no docutils).

Roles and literals become their text (``:class:`~a.B``` → ``B``), ``:math:`` and ``.. math::``
become readable symbols (``\\tau`` → ``τ``), admonitions become labels (``.. note::`` → ``Note:``),
``::`` ends a paragraph with ``:``, and paragraphs and list items are re-wrapped to the width;
literal blocks, doctests and section underlines are kept as they are.
"""

from __future__ import annotations

import re
import textwrap

__all__ = ["inline_text", "latex_text", "rst_to_text"]

_GREEK = [
    "alpha",
    "α",
    "beta",
    "β",
    "gamma",
    "γ",
    "delta",
    "δ",
    "epsilon",
    "ε",
    "varepsilon",
    "ε",
    "zeta",
    "ζ",
    "eta",
    "η",
    "theta",
    "θ",
    "kappa",
    "κ",
    "lambda",
    "λ",
    "mu",
    "μ",
    "nu",
    "ν",
    "xi",
    "ξ",
    "pi",
    "π",
    "rho",
    "ρ",
    "sigma",
    "σ",
    "tau",
    "τ",
    "phi",
    "φ",
    "varphi",
    "φ",
    "chi",
    "χ",
    "psi",
    "ψ",
    "omega",
    "ω",
    "Gamma",
    "Γ",
    "Delta",
    "Δ",
    "Theta",
    "Θ",
    "Lambda",
    "Λ",
    "Xi",
    "Ξ",
    "Pi",
    "Π",
    "Sigma",
    "Σ",
    "Phi",
    "Φ",
    "Psi",
    "Ψ",
    "Omega",
    "Ω",
]
_SYMBOLS = {
    **dict(zip(_GREEK[::2], _GREEK[1::2], strict=True)),
    "cdot": "·",
    "times": "×",
    "le": "≤",
    "leq": "≤",
    "ge": "≥",
    "geq": "≥",
    "ne": "≠",
    "neq": "≠",
    "approx": "≈",
    "pm": "±",
    "infty": "∞",
    "sum": "Σ",
    "prod": "Π",
    "int": "∫",
    "partial": "∂",
    "nabla": "∇",
    "to": "→",
    "rightarrow": "→",
    "leftarrow": "←",
    "in": "∈",
    "ldots": "…",
    "dots": "…",
    "cdots": "⋯",
    "quad": "  ",
    "qquad": "    ",
    "lfloor": "⌊",
    "rfloor": "⌋",
    "lceil": "⌈",
    "rceil": "⌉",
}
_ADMONITIONS = {
    "note": "Note",
    "warning": "Warning",
    "tip": "Tip",
    "hint": "Hint",
    "important": "Important",
    "caution": "Caution",
    "attention": "Attention",
    "danger": "Danger",
    "error": "Error",
    "seealso": "See also",
    "todo": "To do",
}
_LITERAL_DIRECTIVES = {"code", "code-block", "sourcecode", "math", "doctest", "literalinclude"}

# One pass, left to right: a literal or role is consumed whole, so what is inside it is never re-read.
_INLINE = re.compile(
    r"(?P<role>:(?P<name>[\w:.+-]+):`(?P<body>[^`]+)`)"
    r"|``(?P<literal>.+?)``"
    r"|`(?P<link>[^`<]+?)\s*<(?P<url>[^`>]+)>`__?"
    r"|`(?P<ref>[^`]+)`__?"
    r"|`(?P<interp>[^`]+)`"
    r"|\*\*(?P<strong>\S(?:.*?\S)?)\*\*"
    r"|(?<![\w*\\])\*(?P<emph>[^\s*](?:[^*]*?[^\s*\\])?)\*(?![\w*])"
)


def _group(term: str) -> str:
    """A fraction's numerator or denominator: bare when it is one term, else in parentheses."""
    term = term.strip()
    return term if re.fullmatch(r"[^\s+\-*/]+", term) else f"({term})"


def latex_text(tex: str) -> str:
    """LaTeX math as readable text: ``\\tau \\cdot x_{i}^{2}`` → ``τ · x_i^2``, fractions as ``(a)/(b)``."""
    s = tex
    s = re.sub(r"\\(?:mathrm|text|mathbf|mathit|operatorname|mathcal|boldsymbol)\{([^{}]*)\}", r"\1", s)
    for _ in range(4):  # nested fractions and roots, innermost first
        s = re.sub(r"\\[dt]?frac\{([^{}]*)\}\{([^{}]*)\}", lambda m: f"{_group(m[1])}/{_group(m[2])}", s)
        s = re.sub(r"\\sqrt\{([^{}]*)\}", r"√(\1)", s)
    s = re.sub(r"\\(?:left|right|big|Big|bigg|Bigg)\b\s*", "", s)
    s = re.sub(r"\\([A-Za-z]+)", lambda m: _SYMBOLS.get(m.group(1), m.group(1)), s)
    s = re.sub(r"\\[,;:! ]", " ", s)
    s = re.sub(
        r"([_^])\{([^{}]*)\}",
        lambda m: m.group(1) + (m.group(2) if len(m.group(2)) == 1 else f"({m.group(2)})"),
        s,
    )
    s = s.replace("\\{", "{").replace("\\}", "}").replace("{", "").replace("}", "")
    return re.sub(r"[ \t]{2,}", " ", s).strip()


def _inline_one(m: re.Match[str]) -> str:
    if m.group("role"):
        name, body = m.group("name"), m.group("body")
        if name == "math":
            return latex_text(body)
        titled = re.fullmatch(r"\s*(.*?)\s*<[^<>]+>\s*", body, re.S)
        if titled and titled.group(1):
            return titled.group(1)
        body = body.strip()
        if body.startswith("~"):
            return body[1:].rsplit(".", 1)[-1]
        return body.lstrip("!")
    if m.group("literal") is not None:
        return m.group("literal")
    if m.group("link") is not None:
        return f"{m.group('link')} ({m.group('url')})"
    for group in ("ref", "interp", "strong", "emph"):
        if m.group(group) is not None:
            return m.group(group)
    return m.group(0)


def inline_text(text: str) -> str:
    """One paragraph's inline markup as plain text (roles, literals, links, emphasis, escapes)."""
    return _INLINE.sub(_inline_one, text).replace("\\*", "*").replace("\\ ", "")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


_BULLET = re.compile(r"^(\s*)([*+-]|\d+[.)]|#\.|\(\d+\))\s+")
_UNDERLINE = re.compile(r"^\s*([=\-~^\"'`#*+])\1{2,}\s*$")


def rst_to_text(doc: str, width: int = 100) -> str:
    """``doc`` (a docstring, already dedented) as plain text wrapped to ``width`` columns."""
    lines = doc.expandtabs(4).splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            out.append("")
            i += 1
            continue
        directive = re.match(r"^(\s*)\.\.\s+([\w-]+)::\s*(.*)$", line)
        if directive:
            i = _directive(lines, i, directive, out)
            continue
        if re.match(r"^\s*\.\.(\s|$)", line):  # a comment or a link target: not for readers
            i = _skip_block(lines, i + 1, _indent(line))
            continue
        if line.lstrip().startswith(">>>"):
            while i < len(lines) and lines[i].strip():
                out.append(lines[i].rstrip())
                i += 1
            continue
        i = _paragraph(lines, i, out, width)
    text = "\n".join(out)
    return re.sub(r"\n{3,}", "\n\n", text).strip("\n")


def _skip_block(lines: list[str], i: int, indent: int) -> int:
    """Index of the first line after the block indented more than ``indent`` that starts at ``i``."""
    while i < len(lines) and (not lines[i].strip() or _indent(lines[i]) > indent):
        i += 1
    return i


def _literal(lines: list[str], i: int, indent: int, out: list[str], convert: bool = False) -> int:
    """Copy the literal block (lines indented more than ``indent``) starting at ``i``; its end."""
    end = _skip_block(lines, i, indent)
    while end > i and not lines[end - 1].strip():
        end -= 1
    for line in lines[i:end]:
        if convert and line.strip():
            out.append(" " * _indent(line) + latex_text(line.strip()))
        else:
            out.append(line.rstrip())
    return end


def _directive(lines: list[str], i: int, m: re.Match[str], out: list[str]) -> int:
    indent, name, arg = len(m.group(1)), m.group(2).lower(), m.group(3).strip()
    body = i + 1
    while body < len(lines) and re.match(r"^\s+:[\w-]+:", lines[body]) and _indent(lines[body]) > indent:
        body += 1  # directive options (:linenos:, :caption: ...)
    if name in _LITERAL_DIRECTIVES:
        if name == "math" and arg:
            out.append(" " * (indent + 4) + latex_text(arg))
        return _literal(lines, body, indent, out, convert=name == "math")
    label = _ADMONITIONS.get(name, name.replace("-", " ").capitalize())
    out.append(" " * indent + f"{label}:" + (f" {inline_text(arg)}" if arg else ""))
    return body


def _paragraph(lines: list[str], i: int, out: list[str], width: int) -> int:
    """Wrap the paragraph starting at ``i`` item by item; follow a closing ``::`` with its literal block."""
    start = i
    while i < len(lines) and lines[i].strip() and not re.match(r"^\s*\.\.\s", lines[i]):
        if lines[i].lstrip().startswith(">>>"):
            break
        i += 1
    block = lines[start:i]
    base = _indent(block[0])
    literal_follows = block[-1].rstrip().endswith("::")
    if literal_follows:
        last = block[-1].rstrip()[:-2]  # "Text::" -> "Text:", "Text ::" -> "Text", a lone "::" -> nothing
        block[-1] = last.rstrip() if last.endswith((" ", "\t")) or not last.strip() else last + ":"
        if not block[-1].strip():
            block.pop()
    for prefix, hang, words in _items(block):
        if _UNDERLINE.match(words) or (prefix.strip() == "" and words.strip() == ""):
            out.append(prefix + words)
            continue
        text = inline_text(words)
        out.append(
            textwrap.fill(
                text,
                width=max(width, len(hang) + 20),
                initial_indent=prefix,
                subsequent_indent=hang,
                break_long_words=False,
                break_on_hyphens=False,
            )
        )
    if literal_follows:
        j = i
        while j < len(lines) and not lines[j].strip():
            j += 1
        if j < len(lines) and _indent(lines[j]) > base:
            out.append("")
            return _literal(lines, j, base, out)
    return i


def _items(block: list[str]) -> list[tuple[str, str, str]]:
    """The block's items as (first-line prefix, continuation indent, joined words)."""
    items: list[tuple[str, str, list[str]]] = []
    for line in block:
        bullet = _BULLET.match(line)
        ind = _indent(line)
        if _UNDERLINE.match(line) or (items and _UNDERLINE.match(items[-1][2][-1])):
            items.append((" " * ind, " " * ind, [line.strip()]))
        elif bullet:
            prefix = bullet.group(0)
            items.append((prefix, " " * len(prefix), [line[len(prefix) :].strip()]))
        elif items and ind == len(items[-1][1]):
            items[-1][2].append(line.strip())
        else:
            items.append((" " * ind, " " * ind, [line.strip()]))
    return [(p, h, " ".join(w)) for p, h, w in items]
