"""The documentation pages, for whoever has tankdaq: ``tankdaq docs [TOPIC]`` and ``tankdaq.docs(TOPIC)``.

``--help`` texts and docstrings cite ``docs/<topic>.md``; a pip user has no clone, so the wheel carries
those pages (``tankdaq/_docs``, with the example notebook in ``tankdaq/_examples``) and this module
finds them there, or in the source checkout's ``docs/`` and ``examples/``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from ..config import validation
from ..errors import ConfigError, InputError
from ..store.safe_write import new_path
from . import arguments

_HERE = Path(__file__).resolve().parent.parent  # the tankdaq package


def _folder(shipped: str, checkout: str) -> Path:
    """The installed copy's folder (in the wheel) or the source checkout's."""
    for candidate in (_HERE / shipped, _HERE.parent.parent / checkout):
        if candidate.is_dir():
            return candidate
    raise ConfigError(
        f"cannot find tankdaq's {checkout} folder (neither {shipped} in the package nor a checkout)"
    )


def docs_folder() -> Path:
    """Where the documentation pages are (``docs/<topic>.md``)."""
    return _folder("_docs", "docs")


def examples_folder() -> Path:
    """Where the example notebook and its files are (``examples/``)."""
    return _folder("_examples", "examples")


def topics() -> dict[str, str]:
    """Every page's topic (its file name without ``.md``) and title (its first heading)."""
    found = {}
    for page in sorted(docs_folder().glob("*.md")):
        heading = next((line for line in page.read_text(encoding="utf-8").splitlines() if line.strip()), "")
        found[page.stem] = heading.lstrip("#").strip()
    return found


def docs(topic: str | None = None) -> str:
    """One documentation page's text (Markdown), e.g. ``docs("catalogue")``; without a topic, the list of
    topics with their titles. An unknown topic is an ``InputError`` naming the topics there are."""
    topic = arguments.optional_text(topic, "topic", "a page's name (tankdaq.docs() lists them) or None")
    known = topics()
    if topic is None:
        width = max(map(len, known), default=0)
        lines = [f"{name:<{width}}  {title}" for name, title in known.items()]
        return "\n".join([*lines, f"(pages in {docs_folder()}; examples in {examples_folder()})"])
    name = topic.removeprefix("docs/").removesuffix(".md")
    if name not in known:
        raise InputError(f"no docs page {topic!r}: the topics are {', '.join(known)}")
    return (docs_folder() / f"{name}.md").read_text(encoding="utf-8")


def copy_examples(folder: str | Path) -> list[Path]:
    """Copy the example notebook and the small files the docs' examples read into ``folder`` (created;
    a file already there is refused, never replaced): a pip user's ``examples/``. The files written."""
    target = validation.output_dir(Path(folder), "--examples")
    written = []
    for source in sorted(examples_folder().iterdir()):
        if source.is_file() and not source.name.startswith("."):
            target.mkdir(parents=True, exist_ok=True)
            with new_path(target / source.name) as temporary:
                shutil.copyfile(source, temporary)
            written.append(target / source.name)
    return written
