"""Output any console can show: a character the stream's encoding cannot encode is written as plain text
(``B̂44`` -> ``B44_hat``, ``°`` -> ``deg``, ``²`` -> ``2``, ``—`` -> ``-``, ``≈`` -> ``~``), exactly those
characters; every other character is written as it is.

A Windows console or a file in cp1252, or a stream set to ASCII (``PYTHONIOENCODING=ascii``), cannot encode
B̂44's combining hat or ``≈``, and Python's strict default raised UnicodeEncodeError in the middle of a
report. ``install`` runs once, at the entry point (``cli.main``), and sets an error handler on stdout and
stderr, so every writer (``print``, ``typer.echo``, rich's consoles, ``csv``) is covered by one rule.
"""

from __future__ import annotations

import codecs
import io
import re
import sys
import unicodedata

#: The error handler's name (``codecs.register_error``).
HANDLER = "tankdaq-plain"
#: ASCII under a name of its own: click rewraps a stream it sees as ASCII in UTF-8 (a misconfigured
#: locale, it assumes), which bypasses the handler; under this name click writes to the stream as it is.
PLAIN_ASCII = "tankdaq_plain_ascii"
#: A combining circumflex: the hat of ``B̂44``.
HAT = "\u0302"

#: Plain text for the characters tankdaq prints; others: their compatibility form without accents
#: (``é`` -> ``e``, ``³`` -> ``3``), a Greek letter its name (``ρ`` -> ``rho``), else ``?``.
PLAIN = {
    HAT: "_hat",
    "°": "deg",
    "—": "-",
    "–": "-",
    "≈": "~",
    "±": "+/-",
    "×": "x",
    "·": "*",
    "√": "sqrt",
    "∇": "nabla",
    "≤": "<=",
    "≥": ">=",
    "→": "->",
    "…": "...",
    "§": "S",
    "µ": "u",
}

_DIGITS = re.compile(r"[0-9]*")


def plain(char: str) -> str:
    """One character as plain ASCII text."""
    if char in PLAIN:
        return PLAIN[char]
    name = unicodedata.name(char, "")
    if name.startswith("GREEK "):
        letter = name.split()[-1].lower()
        return letter.capitalize() if " CAPITAL " in name else letter
    decomposed = "".join(c for c in unicodedata.normalize("NFKD", char) if not unicodedata.combining(c))
    return decomposed if decomposed and decomposed.isascii() else "?"


def _plain_text(error: UnicodeError) -> tuple[str, int]:
    """The codec error handler: the characters that could not be encoded, as plain text. A hat is
    written after the digits it heads (``B̂44`` -> ``B44_hat``, as the tables' ``b44_hat``)."""
    if not isinstance(error, UnicodeEncodeError):
        raise error
    text, position, out = error.object, error.start, []
    while position < error.end:
        char = text[position]
        position += 1
        if char == HAT:
            digits = _DIGITS.match(text, position).group()  # type: ignore[union-attr]  # [0-9]* matches
            out.append(digits + PLAIN[HAT])
            position += len(digits)
        else:
            out.append(plain(char))
    return "".join(out), position


def _search(name: str) -> codecs.CodecInfo | None:
    """``PLAIN_ASCII``: the ASCII codec under its own name."""
    if name != PLAIN_ASCII:
        return None
    ascii_codec = codecs.lookup("ascii")
    return codecs.CodecInfo(
        ascii_codec.encode,
        ascii_codec.decode,
        incrementalencoder=ascii_codec.incrementalencoder,
        incrementaldecoder=ascii_codec.incrementaldecoder,
        streamreader=ascii_codec.streamreader,
        streamwriter=ascii_codec.streamwriter,
        name=PLAIN_ASCII,
    )


def install() -> None:
    """stdout and stderr write what their encoding cannot encode as plain text (a UTF-8 stream is left as
    it is: it encodes everything)."""
    codecs.register_error(HANDLER, _plain_text)
    codecs.register(_search)
    for stream in (sys.stdout, sys.stderr):
        if not isinstance(stream, io.TextIOWrapper):
            continue  # replaced by the caller (a test runner's capture): theirs to encode
        encoding = codecs.lookup(stream.encoding).name
        if encoding.startswith("utf"):
            continue
        stream.reconfigure(encoding=PLAIN_ASCII if encoding == "ascii" else None, errors=HANDLER)
