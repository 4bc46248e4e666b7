"""`/docs`, the interactive API page: Swagger UI served from the package (`fastapi-offline`),
so that it works on a robot hub without internet: the page names no other host, and every
script, style and icon it references is served by semloc itself."""

from __future__ import annotations

import re
import urllib.request

from semloc.serve.app import DOCS_STATIC


def fetched(url: str) -> tuple[int, bytes]:
    with urllib.request.urlopen(url, timeout=30) as answer:
        return answer.status, answer.read()


def test_the_docs_page_loads_nothing_from_another_host(serve):
    server = serve()
    status, body = fetched(f"{server.url}/docs")
    page = body.decode()
    assert status == 200 and "SwaggerUIBundle" in page
    references = re.findall(r'(?:src|href|url)\s*[=:]\s*[\'"]([^\'"]+)[\'"]', page)
    assert references, page
    assert not [r for r in references if re.match(r"^(https?:)?//", r)], references
    assert not re.search(r"https?://(?!127\.0\.0\.1|localhost)", page), page
    assets = [r for r in references if r.startswith(DOCS_STATIC)]
    assert {a.rsplit("/", 1)[1] for a in assets} >= {"swagger-ui-bundle.js", "swagger-ui.css"}
    for asset in assets:
        status, content = fetched(f"{server.url}{asset}")
        assert status == 200 and len(content) > 1000, asset
    assert "/openapi.json" in references
