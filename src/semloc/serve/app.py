"""The HTTP API of `semloc serve` (FastAPI): routes, access checks, body limits, JSON errors.

Every route is under `/v1`; every error is `{"error": "...", "detail": ...}` with its status
(400 unreadable JSON, 401 no or unknown token, 403 no right, 404 unknown map or session or a map
the token may not see, 409 conflict, 413 body too large, 422 wrong content, 429 too many
requests).  Bodies are read with a size limit and parsed with semloc's JSON reader (no NaN,
no duplicate keys); the localization itself runs in the server's thread pool, so one process
serves many devices at once.  `GET /` is a read-only page (maps, versions, live sessions).
"""

from __future__ import annotations

import datetime
import logging
from importlib import resources
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

import semloc
from semloc.io.reading import parse_json
from semloc.serve.access import Access, Gate, Grant, Refused
from semloc.serve.service import Service, ServiceError, not_found

log = logging.getLogger("semloc.serve")
DEFAULT_MAX_BODY = 64 * 2**20


def create_app(
    service: Service,
    access: Access | None = None,
    rate: float = 100.0,
    max_body: int = DEFAULT_MAX_BODY,
) -> FastAPI:
    """The ASGI app over `service`; `rate` requests per second per token (0: no limit)."""
    access = access or Access.open()
    gate = Gate(access, rate)
    app = FastAPI(
        title="semloc",
        version=semloc.__version__,
        description="Object-level relocalization as a service: shared object maps, one-shot "
        "localization, live sessions and change reports.",
        docs_url="/docs",
        redoc_url=None,
    )
    app.state.service, app.state.access = service, access

    def identify(request: Request) -> Grant:
        """The caller's grant (401 without a valid token), within its request rate and, for
        failed logins, its address's rate (429)."""
        try:
            return gate.admit(_token(request), request.client.host if request.client else "")
        except Refused as exc:
            status = 401 if exc.reason == "unauthorized" else 429
            raise ServiceError(status, exc.reason, exc.detail) from None

    def check(grant: Grant, map_id: str, right: str) -> None:
        """404 for a map the grant may not see (as for one that does not exist), 403 for a
        right it lacks."""
        if not grant.sees(map_id):
            raise not_found(f"map {map_id!r}")
        if right not in grant.rights(map_id):
            raise ServiceError(403, "forbidden", f"this token may not {right} map {map_id!r}")

    def authorize(request: Request, map_id: str, right: str) -> Grant:
        grant = identify(request)
        check(grant, map_id, right)
        return grant

    async def body(request: Request, optional: bool = False) -> Any:
        declared = request.headers.get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > max_body:
            raise ServiceError(413, "body too large", f"at most {max_body:,} bytes")
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > max_body:
                raise ServiceError(413, "body too large", f"at most {max_body:,} bytes")
            chunks.append(chunk)
        raw = b"".join(chunks)
        if optional and not raw.strip():
            return None
        try:
            return parse_json(raw.decode("utf-8"))
        except UnicodeDecodeError:
            raise ServiceError(400, "bad JSON", "the body is not UTF-8") from None
        except RecursionError:
            raise ServiceError(400, "bad JSON", "nested too deeply") from None
        except ValueError as exc:
            raise ServiceError(400, "bad JSON", str(exc)[:200]) from None

    @app.exception_handler(ServiceError)
    async def _service_error(request: Request, exc: ServiceError) -> JSONResponse:
        headers = {"WWW-Authenticate": "Bearer"} if exc.status == 401 else None
        if exc.status == 429:
            headers = {"Retry-After": "1"}
        return JSONResponse({"error": exc.error, "detail": exc.detail}, exc.status, headers)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return JSONResponse({"error": str(exc.detail).lower(), "detail": None}, exc.status_code)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        detail = [{"loc": list(e.get("loc", ())), "msg": e.get("msg")} for e in exc.errors()]
        return JSONResponse({"error": "invalid request", "detail": detail}, 422)

    @app.exception_handler(Exception)
    async def _internal_error(request: Request, exc: Exception) -> JSONResponse:
        log.exception("internal error on %s %s", request.method, request.url.path)
        return JSONResponse({"error": "internal error", "detail": type(exc).__name__}, 500)

    @app.get("/v1/health")
    async def health() -> dict[str, Any]:
        return {"status": "ok", "version": semloc.__version__,
                "store": type(service.store).__name__, "tokens": access.required}  # fmt: skip

    @app.get("/v1/maps")
    async def list_maps(request: Request) -> list[dict[str, Any]]:
        grant = identify(request)
        found = await run_in_threadpool(service.store.map_ids)
        return [{"map_id": m, "version": v} for m, v in found if "read" in grant.rights(m)]

    @app.put("/v1/maps/{map_id}", status_code=201)
    async def put_map(map_id: str, request: Request) -> dict[str, Any]:
        authorize(request, map_id, "write")
        document = await body(request)
        version = await run_in_threadpool(service.put_map, map_id, document)
        return {"map_id": map_id, "version": version}

    @app.get("/v1/maps/{map_id}")
    async def get_map(map_id: str, request: Request, version: int | None = None) -> Response:
        authorize(request, map_id, "read")
        if version is not None and version < 1:
            raise ServiceError(422, "invalid version", "versions are integers from 1")
        number, document = await run_in_threadpool(service.map_document, map_id, version)
        return JSONResponse(document, headers={"X-Semloc-Map-Version": str(number)})

    @app.get("/v1/maps/{map_id}/versions")
    async def versions(map_id: str, request: Request) -> list[dict[str, Any]]:
        authorize(request, map_id, "read")
        found = await run_in_threadpool(service.store.versions, map_id)
        if not found:
            raise not_found(f"map {map_id!r}")
        return [{"version": v.version, "created": _iso(v.created), "source": v.source}
                for v in found]  # fmt: skip

    @app.post("/v1/maps/{map_id}/localize")
    async def localize(map_id: str, request: Request) -> JSONResponse:
        authorize(request, map_id, "localize")
        document = await body(request)
        return JSONResponse(await run_in_threadpool(service.localize, map_id, document))

    @app.post("/v1/maps/{map_id}/sessions", status_code=201)
    async def create_session(map_id: str, request: Request) -> dict[str, Any]:
        authorize(request, map_id, "localize")
        document = await body(request, optional=True)
        session_id = await run_in_threadpool(service.create_session, map_id, document)
        return {"session_id": session_id}

    @app.get("/v1/maps/{map_id}/sessions")
    async def list_sessions(map_id: str, request: Request) -> list[dict[str, Any]]:
        authorize(request, map_id, "read")
        return await run_in_threadpool(service.sessions, map_id)

    @app.post("/v1/sessions/{session_id}/objects")
    async def update_session(session_id: str, request: Request) -> JSONResponse:
        grant = identify(request)
        check(grant, await run_in_threadpool(service.session_map, session_id), "localize")
        document = await body(request)
        return JSONResponse(await run_in_threadpool(service.update_session, session_id, document))

    @app.delete("/v1/sessions/{session_id}", status_code=204)
    async def delete_session(session_id: str, request: Request) -> Response:
        grant = identify(request)
        check(grant, await run_in_threadpool(service.session_map, session_id), "localize")
        await run_in_threadpool(service.delete_session, session_id)
        return Response(status_code=204)

    @app.post("/v1/maps/{map_id}/changes", status_code=201)
    async def report_changes(map_id: str, request: Request) -> Response:
        authorize(request, map_id, "write")
        document = await body(request)
        version, written = await run_in_threadpool(service.report_changes, map_id, document)
        return JSONResponse({"version": version, "changed": written}, 201 if written else 200)

    @app.get("/", include_in_schema=False)
    async def page() -> HTMLResponse:
        html = resources.files("semloc.serve").joinpath("page.html").read_text(encoding="utf-8")
        return HTMLResponse(html)

    return app


def _token(request: Request) -> str | None:
    header = request.headers.get("authorization", "")
    scheme, _, value = header.partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


def _iso(seconds: float) -> str:
    return datetime.datetime.fromtimestamp(seconds, datetime.UTC).isoformat(timespec="milliseconds")
