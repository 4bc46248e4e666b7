"""`semloc serve`: object-level localization as a service for a fleet (extra `semloc[serve]`).

    store.py    map versions and sessions in SQLite (default) or PostgreSQL, one transaction
                per write
    access.py   the token file, rights per map, request rates
    service.py  what the service does: versions, localization, owned sessions, change
                reports, request keys (safe retries); its refusals by kind
    models.py   the shapes of every request body and answer (pydantic; /openapi.json)
    app.py      the HTTP API under /v1 (FastAPI): routes, dependencies (token, rights,
                bodies), the one place of HTTP status codes; the page at /
    server.py   settings and running it (uvicorn, one or several worker processes, or a
                thread of this process: `serving`)

The client is `semloc.client.Client`; the API is described in docs/serve.md.  Importing this
package needs the `serve` extra (FastAPI, uvicorn).
"""

from semloc.serve.server import ServeSettings, serving

__all__ = ["ServeSettings", "serving"]
