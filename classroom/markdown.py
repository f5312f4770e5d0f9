"""Exercise texts: a teacher's Markdown as HTML that is safe to show to students.

Two layers, so a mistake in one is caught by the other: markdown-it-py renders with raw HTML
off (a teacher's ``<script>`` comes out as text), then nh3 keeps only the tags Markdown makes,
links to http(s), mailto or this site (each with ``rel="noopener noreferrer"``), and images
from this site only (no other host sees who reads the exercise; no ``data:``). No style
attributes (the CSP refuses inline styles; tables' column alignment is dropped). Headings go
one level down: the page showing the text has its own title.
"""

from functools import cache

import nh3
from django.utils.safestring import SafeString, mark_safe
from markdown_it import MarkdownIt

TAGS = {
    "a", "blockquote", "br", "code", "del", "em", "h1", "h2", "h3", "h4", "h5", "h6", "hr",
    "img", "li", "ol", "p", "pre", "s", "strong", "table", "tbody", "td", "th", "thead", "tr",
    "ul",
}  # fmt: skip
ATTRIBUTES = {
    "a": {"href", "title"},
    "img": {"src", "alt", "title"},
    "ol": {"start"},
}
URL_SCHEMES = {"http", "https", "mailto"}


@cache
def _parser() -> MarkdownIt:
    return MarkdownIt("commonmark", {"html": False, "linkify": False, "typographer": False}).enable(
        ["table", "strikethrough"]
    )


def _same_origin(url: str) -> bool:
    """A path on this site: "/static/x.png" or "pic.png", not "//host/x" nor "https://…"."""
    url = url.strip()
    if not url or url.startswith(("//", "\\", "/\\")):
        return False
    return ":" not in url.split("/", 1)[0].split("?", 1)[0].split("#", 1)[0]


def _attribute_filter(tag: str, attribute: str, value: str) -> str | None:
    if tag == "img" and attribute == "src" and not _same_origin(value):
        return None
    return value


def render(text: str) -> SafeString:
    """``text`` (Markdown) as sanitised HTML."""
    parser = _parser()
    tokens = parser.parse(text or "")
    for token in tokens:  # the page's own title is its h1: the text's headings one level down
        if token.type in ("heading_open", "heading_close"):
            token.tag = f"h{min(6, int(token.tag[1]) + 1)}"
    html = parser.renderer.render(tokens, parser.options, {})
    cleaned = nh3.clean(
        html,
        tags=TAGS,
        clean_content_tags={"script", "style"},
        attributes=ATTRIBUTES,
        attribute_filter=_attribute_filter,
        url_schemes=URL_SCHEMES,
        link_rel="noopener noreferrer",
    )
    return mark_safe(cleaned)
