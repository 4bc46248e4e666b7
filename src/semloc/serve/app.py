"""The HTTP API of `semloc serve` (FastAPI): routes, access checks, body limits, status codes.

This module is the one place that decides HTTP status codes: the service refuses with a kind
of error (`semloc.serve.service`), each route answers with the status of that kind.  Every
route is under `/v1` and declares its body, its answers and its errors in `/openapi.json`
(models in `semloc.serve.models`); every error is `{"error": "...", "detail": ...}`:

    400 unreadable JSON         401 no or unknown token       403 no right on the map
    404 unknown map, version or session, a map the token may not see, another's session
    409 conflicting change report   412 If-Match no longer holds   413 body too large
    422 content that is not what the route takes (also a reused Idempotency-Key)
    429 too many requests (with Retry-After)

Bodies are read with a size limit and parsed with semloc's JSON reader (no NaN, no duplicate
keys), then checked against the route's model, in the server's thread pool like the
localization itself, so one process serves many devices at once.  Who may do what is a
dependency of each route (`Depends`): the bearer token, its rights on the map, its rate.
`GET /` is a read-only page (maps, versions, live sessions); `GET /v1/ready` says whether the
store answers (503 if not); `GET /metrics` gives the Prometheus metrics of `semloc.serve.observe`
to a loopback client or a token with a right on every map (`*`).
"""

import asyncio
import datetime
import ipaddress
import logging
import math
import re
import sqlite3
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from importlib import resources
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Header, Path, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, PlainTextResponse, Response
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from fastapi_offline import FastAPIOffline
from pydantic import BaseModel, ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

import semloc
from semloc.io.reading import parse_json
from semloc.serve import models
from semloc.serve.access import ANY_MAP, Access, Gate, Grant, digest
from semloc.serve.access import Refused as AccessRefused
from semloc.serve.observe import ObserveMiddleware, Observer
from semloc.serve.service import (
    Conflict,
    Expected,
    Idempotency,
    Invalid,
    NotFound,
    PreconditionFailed,
    Service,
    ServiceError,
    not_found,
)

log = logging.getLogger("semloc.serve")
DEFAULT_MAX_BODY = 64 * 2**20
READY_TIMEOUT_S = 5.0
STATUS: dict[type[ServiceError], int] = {
    Invalid: 422,
    NotFound: 404,
    Conflict: 409,
    PreconditionFailed: 412,
}
"""The HTTP status of each kind of refusal of the service."""


class Refused(Exception):
    """A refusal of the web layer itself, with its HTTP status."""

    def __init__(self, status: int, error: str, detail: Any = None) -> None:
        super().__init__(error)
        self.status, self.error, self.detail = status, error, detail


@dataclass(frozen=True)
class Body:
    """A request body: its document (checked against the route's model) and its bytes."""

    document: Any
    raw: bytes


@dataclass(frozen=True)
class Caller:
    """Who is asking: the token's rights, and the owner its sessions and request keys belong
    to (the token's digest; one owner for everyone without a token file)."""

    grant: Grant
    owner: str


# What each route may answer besides its success (declared in /openapi.json) -----------------
_ERRORS = {
    400: "Unreadable JSON (not UTF-8, NaN, duplicate keys, nested too deeply).",
    401: "No token, or an unknown one.",
    403: "The token lacks the right on this map.",
    404: "Unknown map, version or session, or one the token may not see.",
    409: "The change report conflicts with versions written since its answer.",
    412: "If-Match: the map's latest version is another.",
    413: "The body is larger than the server takes.",
    422: "The content is not what the route takes.",
    429: "Too many requests: retry after Retry-After seconds.",
}


def _errors(*statuses: int) -> dict[int | str, dict[str, Any]]:
    found: dict[int | str, dict[str, Any]] = {
        status: {"model": models.Error, "description": _ERRORS[status]} for status in statuses
    }
    if 429 in statuses:
        found[429]["headers"] = {
            "Retry-After": {"description": "Seconds to wait.", "schema": {"type": "integer"}}
        }
    if 401 in statuses:
        found[401]["headers"] = {"WWW-Authenticate": {"schema": {"type": "string"}}}
    return found


AUTH = (401, 404, 422, 429)  # any route with a token: 404 a map it may not see, 422 bad params
BODY = (400, 413, 422)


def _body(model: type[BaseModel], required: bool = True) -> dict[str, Any]:
    """The `requestBody` of a route that reads its body itself (semloc's JSON reader)."""
    return {
        "requestBody": {
            "required": required,
            "content": {
                "application/json": {"schema": {"$ref": f"#/components/schemas/{model.__name__}"}}
            },
        }
    }


def _etag(version: int) -> dict[str, str]:
    return {"ETag": f'"{version}"'}


ETAG = {"ETag": {"description": 'The version: "<version>".', "schema": {"type": "string"}}}


MAP_ONLY = re.compile(r"map '.*'", re.S)
"""The detail of a 404 about a map as a whole (not one of its versions)."""
MAP_HINT = " (or your token may not see it)"
"""Added to such a 404: a map the token may not see is answered as one that does not exist."""
DOCS_STATIC = "/docs/static"
"""Where the interactive page's scripts, styles and icon are served (from `fastapi-offline`)."""


def create_app(
    service: Service,
    access: Access | None = None,
    rate: float = 100.0,
    max_body: int = DEFAULT_MAX_BODY,
    access_log: bool = False,
) -> FastAPI:
    """The ASGI app over `service`; `rate` requests per second per token (0: no limit);
    `access_log`: one JSON line per request on the `semloc.serve.access` logger."""
    access = access or Access.open()
    gate = Gate(access, rate)
    observer = Observer(lambda: service.store.live_sessions(service.session_idle_s))

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        yield
        service.store.close()

    app = FastAPIOffline(  # /docs: Swagger UI served from the package, no CDN
        title="semloc",
        version=semloc.__version__,
        description="Object-level relocalization as a service: shared object maps, one-shot "
        "localization, live sessions and change reports.",
        docs_url="/docs",
        redoc_url=None,
        static_url=DOCS_STATIC,
        lifespan=lifespan,
        separate_input_output_schemas=True,  # answers as written: what is always there is required
    )
    app.state.service, app.state.access, app.state.observer = service, access, observer
    app.add_middleware(ObserveMiddleware, observer=observer, access_log=access_log)
    bearer = HTTPBearer(auto_error=False, description="A token of the server's token file.")

    # dependencies: who is asking, and may they ---------------------------------------------
    async def caller(
        request: Request,
        credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
    ) -> Caller:
        """The caller (401 without a valid token), within its request rate and, for failed
        logins, its address's rate (429)."""
        token = credentials.credentials if credentials else None
        address = request.client.host if request.client else ""
        try:  # failed logins count against the address's rate
            grant = gate.admit(token, address)
        except AccessRefused as exc:
            status = 401 if exc.reason == "unauthorized" else 429
            raise Refused(status, exc.reason, exc.detail) from None
        request.state.caller = grant.name  # for the access log: never the token
        return Caller(grant, digest(token) if access.required and token else "")

    Who = Annotated[Caller, Depends(caller)]
    MapPath = Annotated[str, Path(min_length=1, max_length=200, pattern=models.ID_PATTERN)]
    SessionPath = Annotated[str, Path(min_length=1, max_length=200)]
    Key = Annotated[
        str | None,
        Header(
            alias="Idempotency-Key",
            min_length=1,
            max_length=200,
            pattern=r"^[!-~]+$",
            description="Names this write: sent again with the same body, the first answer "
            "comes back and nothing more is written; with another body, 422.",
        ),
    ]

    def check(grant: Grant, map_id: str, right: str) -> None:
        """404 for a map the grant may not see (as for one that does not exist), 403 for a
        right it lacks."""
        if not grant.sees(map_id):
            raise not_found(f"map {map_id!r}")
        if right not in grant.rights(map_id):
            raise Refused(403, "forbidden", f"this token may not {right} map {map_id!r}")

    def may(right: str) -> Callable[..., Caller]:
        async def dependency(map_id: MapPath, who: Who) -> Caller:
            check(who.grant, map_id, right)
            return who

        return dependency

    def reader(model: type[BaseModel], optional: bool = False) -> Callable[..., Any]:
        """A dependency: the body read (size limit), parsed (semloc's JSON reader) and checked
        against `model`, off the event loop; its document is None for an empty optional body."""

        async def dependency(request: Request) -> Body:
            raw = await _read(request, max_body)
            return Body(await run_in_threadpool(_parsed, raw, model, optional), raw)

        return dependency

    # errors ----------------------------------------------------------------------------------
    @app.exception_handler(ServiceError)
    async def _service_error(request: Request, exc: ServiceError) -> JSONResponse:
        detail = exc.detail
        if isinstance(exc, NotFound) and isinstance(detail, str) and MAP_ONLY.fullmatch(detail):
            detail += MAP_HINT  # the same words whether it is absent or hidden from this token
        return _error(STATUS.get(type(exc), 422), exc.error, detail)

    @app.exception_handler(Refused)
    async def _refused(request: Request, exc: Refused) -> JSONResponse:
        headers = {"WWW-Authenticate": "Bearer"} if exc.status == 401 else None
        if exc.status == 429:
            headers = {"Retry-After": str(max(1, math.ceil(1 / rate)) if rate > 0 else 1)}
        return _error(exc.status, exc.error, exc.detail, headers)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        headers = dict(exc.headers or {})
        if exc.status_code == 405:  # every method of the path, not only the first route's
            headers["Allow"] = ", ".join(_methods(app, request.url.path))
        return _error(exc.status_code, str(exc.detail).lower(), None, headers or None)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        return _error(422, "invalid request", _problems(exc.errors()))

    @app.exception_handler(Exception)
    async def _internal_error(request: Request, exc: Exception) -> JSONResponse:
        log.exception("internal error on %s %s", request.method, request.url.path)
        if _store_error(exc):
            observer.store_errors.inc()
        return _error(500, "internal error", type(exc).__name__)

    # routes ----------------------------------------------------------------------------------
    @app.get("/v1/health", response_model=models.Health, tags=["service"])
    async def health() -> dict[str, Any]:
        """The server answers (no token needed)."""
        return {"status": "ok", "version": semloc.__version__,
                "store": type(service.store).__name__, "tokens": access.required}  # fmt: skip

    @app.get(
        "/v1/ready",
        response_model=models.Ready,
        tags=["service"],
        responses={503: {"model": models.Error, "description": "The store does not answer."}},
    )
    async def ready() -> JSONResponse:
        """The server can serve: its store answers (no token needed)."""
        try:
            await asyncio.wait_for(run_in_threadpool(service.store.check), READY_TIMEOUT_S)
        except Exception as exc:  # a dead database, a full disk, a timeout: not ready
            observer.store_errors.inc()
            return _error(503, "not ready", f"the store does not answer ({type(exc).__name__})")
        return JSONResponse({"status": "ready"})

    @app.get(
        "/metrics",
        response_class=PlainTextResponse,
        tags=["service"],
        responses={
            200: {"description": "Prometheus text format.",
                  "content": {"text/plain": {"schema": {"type": "string"}}}},
            **{status: {"description": _ERRORS[status], "content": {"application/json": {
                "schema": {"$ref": "#/components/schemas/Error"}}}} for status in (401, 403)},
        },
        openapi_extra={"security": [{}, {"HTTPBearer": []}]},  # no token from loopback
    )  # fmt: skip
    async def metrics(request: Request) -> Response:
        """The Prometheus metrics: for a loopback client, or a token with a right on `*`."""
        if not _loopback(request):
            grant = access.grant(_bearer_token(request))
            if grant is None:
                raise Refused(401, "unauthorized", "a token with a right on '*', or loopback")
            if not grant.maps.get(ANY_MAP):
                raise Refused(403, "forbidden", "the metrics need a right on every map ('*')")
        body, content_type = await run_in_threadpool(observer.exposition)
        return Response(body, media_type=content_type)

    @app.get("/v1/maps", response_model=list[models.MapVersion], tags=["maps"],
             responses=_errors(401, 429))  # fmt: skip
    async def list_maps(who: Who) -> list[dict[str, Any]]:
        """The maps this token may read, with their latest version."""
        found = await run_in_threadpool(service.store.map_ids)
        return [{"map_id": m, "version": v} for m, v in found if "read" in who.grant.rights(m)]

    @app.put(
        "/v1/maps/{map_id}",
        status_code=201,
        response_model=models.MapVersion,
        tags=["maps"],
        responses={201: {"headers": ETAG}, **_errors(*AUTH, *BODY, 403, 412)},
        openapi_extra=_body(models.SemlocMap),
    )
    async def put_map(
        map_id: MapPath,
        who: Annotated[Caller, Depends(may("write"))],
        body: Annotated[Body, Depends(reader(models.SemlocMap))],
        idempotency_key: Key = None,
        if_match: Annotated[
            str | None,
            Header(
                alias="If-Match",
                max_length=200,
                description='Only if the latest version is this one ("N" or N; * for any).',
            ),
        ] = None,
    ) -> JSONResponse:
        """Upload a map: its next version (1 for a new map)."""
        version = await run_in_threadpool(
            service.put_map,
            map_id,
            body.document,
            _expected(if_match),
            Idempotency.of(idempotency_key, body.raw),
            who.owner,
        )
        return JSONResponse({"map_id": map_id, "version": version}, 201, _etag(version))

    @app.get(
        "/v1/maps/{map_id}",
        response_model=models.SemlocMap,
        tags=["maps"],
        responses={200: {"headers": ETAG}, **_errors(*AUTH, 403)},
    )
    async def get_map(
        map_id: MapPath,
        who: Annotated[Caller, Depends(may("read"))],
        version: Annotated[int | None, Query(ge=1, le=models.SAFE_INTEGER)] = None,
    ) -> Response:
        """A map: the latest version, or `version`."""
        number, document = await run_in_threadpool(service.map_document, map_id, version)
        headers = {"X-Semloc-Map-Version": str(number), **_etag(number)}
        return await _json(document, headers=headers)

    @app.delete("/v1/maps/{map_id}", status_code=204, tags=["maps"],
                responses=_errors(*AUTH, 403))  # fmt: skip
    async def delete_map(
        map_id: MapPath, who: Annotated[Caller, Depends(may("write"))]
    ) -> Response:
        """Delete a map: every version, its sessions and kept localizations.  Uploaded again,
        the id goes on from the next version number (a number never names two documents)."""
        await run_in_threadpool(service.delete_map, map_id)
        return Response(status_code=204)

    @app.get("/v1/maps/{map_id}/versions", response_model=list[models.VersionInfo],
             tags=["maps"], responses=_errors(*AUTH, 403))  # fmt: skip
    async def versions(
        map_id: MapPath, who: Annotated[Caller, Depends(may("read"))]
    ) -> list[dict[str, Any]]:
        """Every version of a map, oldest first."""
        found = await run_in_threadpool(service.store.versions, map_id)
        if not found:
            raise not_found(f"map {map_id!r}")
        return [{"version": v.version, "created": _iso(v.created), "source": v.source}
                for v in found]  # fmt: skip

    @app.post(
        "/v1/maps/{map_id}/localize",
        response_model=models.LocalizeAnswer,
        tags=["localization"],
        responses=_errors(*AUTH, *BODY, 403),
        openapi_extra=_body(models.LocalizeRequest),
    )
    async def localize(
        map_id: MapPath,
        who: Annotated[Caller, Depends(may("localize"))],
        body: Annotated[Body, Depends(reader(models.LocalizeRequest))],
    ) -> JSONResponse:
        """Localize a local map (replayed by `seen`) in the latest version, within the body's
        optional position `prior`."""
        answer = await run_in_threadpool(service.localize, map_id, body.document)
        observer.answers.labels("one-shot", answer["status"]).inc()
        return await _json(answer)

    @app.post(
        "/v1/maps/{map_id}/sessions",
        status_code=201,
        response_model=models.SessionCreated,
        tags=["sessions"],
        responses=_errors(*AUTH, *BODY, 403),
        openapi_extra=_body(models.SessionCreate, required=False),
    )
    async def create_session(
        map_id: MapPath,
        who: Annotated[Caller, Depends(may("localize"))],
        body: Annotated[Body, Depends(reader(models.SessionCreate, optional=True))],
    ) -> dict[str, Any]:
        """Open a live session on the latest version; it belongs to this token."""
        session_id = await run_in_threadpool(
            service.create_session, map_id, body.document, who.owner
        )
        return {"session_id": session_id}

    @app.get("/v1/maps/{map_id}/sessions", response_model=list[models.SessionInfo],
             tags=["sessions"], responses=_errors(*AUTH, 403))  # fmt: skip
    async def list_sessions(
        map_id: MapPath, who: Annotated[Caller, Depends(may("read"))]
    ) -> list[dict[str, Any]]:
        """The live sessions of a map: latest status and pose; ids of this token's only."""
        return await run_in_threadpool(service.sessions, map_id, who.owner)

    @app.post(
        "/v1/sessions/{session_id}/objects",
        response_model=models.SessionAnswer,
        tags=["sessions"],
        responses=_errors(*AUTH, *BODY, 403, 409),
        openapi_extra=_body(models.SessionUpdate),
    )
    async def update_session(
        session_id: SessionPath,
        who: Who,
        body: Annotated[Body, Depends(reader(models.SessionUpdate))],
        idempotency_key: Key = None,
    ) -> JSONResponse:
        """The answer after these objects (404 for a session of another token)."""

        def update() -> JSONResponse:  # one trip to the thread pool: a device's every update
            meta = service.session_of(session_id, who.owner)
            check(who.grant, meta.map_id, "localize")
            sent = Idempotency.of(idempotency_key, body.raw)
            answer = service.update_session(session_id, body.document, sent)
            observer.answers.labels("session", answer["status"]).inc()
            return JSONResponse(answer)

        return await run_in_threadpool(update)

    @app.delete("/v1/sessions/{session_id}", status_code=204, tags=["sessions"],
                responses=_errors(*AUTH, 403))  # fmt: skip
    async def delete_session(session_id: SessionPath, who: Who) -> Response:
        """End a session: this token's own, or any session of a map it may write."""
        map_id = await run_in_threadpool(service.session_map, session_id)
        writer = "write" in who.grant.rights(map_id)
        meta = await run_in_threadpool(service.session_of, session_id, who.owner, writer)
        if not writer:
            check(who.grant, meta.map_id, "localize")
        await run_in_threadpool(service.delete_session, session_id)
        return Response(status_code=204)

    @app.post(
        "/v1/maps/{map_id}/changes",
        status_code=201,
        response_model=models.ChangeResult,
        tags=["maps"],
        responses={
            200: {"model": models.ChangeResult, "description": "Nothing changed."},
            **_errors(*AUTH, *BODY, 403, 409),
        },  # fmt: skip
        openapi_extra=_body(models.ChangeReport),
    )
    async def report_changes(
        map_id: MapPath,
        who: Annotated[Caller, Depends(may("write"))],
        body: Annotated[Body, Depends(reader(models.ChangeReport))],
        idempotency_key: Key = None,
    ) -> JSONResponse:
        """Apply what an answer found changed: 201 a new version, 200 nothing changed."""
        found = await run_in_threadpool(
            service.report_changes,
            map_id,
            body.document,
            Idempotency.of(idempotency_key, body.raw),
            who.owner,
        )
        return JSONResponse(found, 201 if found["changed"] else 200)

    @app.get("/", include_in_schema=False)
    async def page() -> HTMLResponse:
        html = resources.files("semloc.serve").joinpath("page.html").read_text(encoding="utf-8")
        return HTMLResponse(html)

    _declare_bodies(app)
    return app


def _declare_bodies(app: FastAPI) -> None:
    """Add the request models that routes read themselves to the OpenAPI components."""
    original = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            components = original().setdefault("components", {}).setdefault("schemas", {})
            for model in models.REQUESTS:
                found = model.model_json_schema(ref_template="#/components/schemas/{model}")
                components.update(found.pop("$defs", {}))
                components[model.__name__] = found
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def _bearer_token(request: Request) -> str | None:
    scheme, _, value = request.headers.get("authorization", "").partition(" ")
    return value.strip() or None if scheme.lower() == "bearer" else None


def _loopback(request: Request) -> bool:
    host = request.client.host if request.client else ""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _store_error(exc: Exception) -> bool:
    """Whether an exception came from the database (SQLite or psycopg)."""
    return isinstance(exc, sqlite3.Error) or type(exc).__module__.startswith("psycopg")


def _methods(app: FastAPI, path: str) -> list[str]:
    """The methods the routes of `path` take."""
    found: set[str] = set()
    for route in app.routes:
        regex, methods = getattr(route, "path_regex", None), getattr(route, "methods", None)
        if regex is not None and methods and regex.match(path):
            found |= set(methods)
    return sorted(found)


# Reading bodies -----------------------------------------------------------------------------
async def _read(request: Request, max_body: int) -> bytes:
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > max_body:
        raise Refused(413, "body too large", f"at most {max_body:,} bytes")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > max_body:
            raise Refused(413, "body too large", f"at most {max_body:,} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


def _parsed(raw: bytes, model: type[BaseModel], optional: bool) -> Any:
    """The body as JSON (400 when unreadable), checked against `model` (422)."""
    if optional and not raw:  # absent; white space alone is not JSON (400)
        return None
    try:
        document = parse_json(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise Refused(400, "bad JSON", "the body is not UTF-8") from None
    except RecursionError:
        raise Refused(400, "bad JSON", "nested too deeply") from None
    except ValueError as exc:
        raise Refused(400, "bad JSON", str(exc)[:200]) from None
    try:
        return models.checked(model, document)
    except ValidationError as exc:
        raise Refused(422, f"invalid {model.__name__}", _problems(exc.errors())) from None


def _problems(errors: Any) -> list[dict[str, Any]]:
    return [{"loc": [str(p) for p in e.get("loc", ())], "msg": e.get("msg")} for e in errors][:20]


def _expected(if_match: str | None) -> Expected | None:
    """The versions an If-Match header accepts: `"N"` or N, a list of them, or `*`; a tag
    that names no version accepts none (412)."""
    if if_match is None:
        return None
    if if_match.strip() == "*":
        return "*"
    versions = []
    for tag in if_match.split(","):
        tag = tag.strip().removeprefix("W/").strip('"')
        if tag.isascii() and tag.isdigit() and len(tag) < 20:
            versions.append(int(tag))
    return versions


async def _json(
    content: Any, status: int = 200, headers: dict[str, str] | None = None
) -> JSONResponse:
    """A JSON answer serialised in the thread pool (a map of many points takes a while: the
    event loop goes on serving the other requests meanwhile)."""
    return await run_in_threadpool(JSONResponse, content, status, headers)


def _error(
    status: int, error: str, detail: Any = None, headers: dict[str, str] | None = None
) -> JSONResponse:
    return JSONResponse({"error": error, "detail": detail}, status, headers)


def _iso(seconds: float) -> str:
    return datetime.datetime.fromtimestamp(seconds, datetime.UTC).isoformat(timespec="milliseconds")
