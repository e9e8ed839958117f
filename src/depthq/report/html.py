"""A self-contained HTML page (figures inlined as data URIs: it renders offline, from any folder)."""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any


def _figure(path: Path, alt: str, element: str) -> str:
    """`element` (with `{src}` for the file as a data URI) in a captioned figure; a note if missing."""
    caption = html.escape(alt)
    if not path.is_file():
        return f"<p><em>{caption}: not produced</em></p>"
    src = base64.b64encode(path.read_bytes()).decode()
    return f"<figure>{element.format(src=src, alt=caption)}<figcaption>{caption}</figcaption></figure>"


def img(path: Path, alt: str) -> str:
    return _figure(path, alt, '<img alt="{alt}" src="data:image/png;base64,{src}">')


def video(path: Path, alt: str) -> str:
    """An MP4 inlined like the figures (H.264 plays in every current browser)."""
    element = '<video controls muted loop title="{alt}" src="data:video/mp4;base64,{src}"></video>'
    return _figure(path, alt, element)


def table(rows: list[dict[str, str]]) -> str:
    if not rows:
        return "<p><em>no rows</em></p>"
    head = "".join(f"<th>{html.escape(h)}</th>" for h in rows[0])
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in r.values()) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def render(title: str, sections: list[tuple[str, str]]) -> str:
    style = (
        "body{font-family:sans-serif;max-width:1200px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:1em 0;font-size:13px}"
        "td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}th{background:#eee}"
        "img,video{max-width:100%}figcaption{font-size:12px;color:#555}pre{background:#f6f6f6;padding:8px;"
        "font-size:12px;overflow:auto}"
    )
    body = "".join(f"<h2>{html.escape(h)}</h2>{content}" for h, content in sections)
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<style>{style}</style></head><body><h1>{html.escape(title)}</h1>{body}</body></html>\n"
    )


def pre(obj: Any) -> str:
    return f"<pre>{html.escape(json.dumps(obj, indent=2))}</pre>"
