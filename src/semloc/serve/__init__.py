"""`semloc serve`: object-level localization as a service for a fleet (extra `semloc[serve]`).

    store.py    map versions and sessions in SQLite (default) or PostgreSQL, one transaction
                per write
    access.py   the token file, rights per map, request rates
    service.py  what the service does: versions, localization, sessions, change reports
    app.py      the HTTP API under /v1 (FastAPI) and the page at /
    server.py   settings and running it (uvicorn, one or several worker processes)

The client is `semloc.client.Client`; the API is described in docs/serve.md.
"""
