"""The HTTP client: :class:`Client` (connections, retries, typed errors) and
:class:`Binding` (a bound mesh that survives eviction and restarts).

Every request of the service's API is safe to repeat (bindings are named by
their content, frames are pure functions of their input, a bake rewrites the
same file), so the client retries whatever did not get a definite answer:

- connection failures (refused, reset, closed before the answer) and the
  statuses 429, 502, 503 and 504, up to ``retries`` times per request, waiting
  ``backoff * 2**attempt`` seconds less up to a quarter at random, or the
  answer's ``Retry-After`` plus up to a quarter when that is longer, never
  more than ``max_backoff`` (the jitter keeps many clients from retrying in step);
- a kept-alive connection found closed when reused (the server restarted,
  or closed it idle): once more at once on a new connection, not counted as
  a retry;
- 404 ``unknown_binding`` on a frame: the :class:`Binding` posts its request
  again (same content, same id) and repeats the frame, up to ``rebinds`` times.

A timeout (no answer within ``timeout`` seconds) is not retried: the server
may still be working on it, and repeating would double its load. It raises
:class:`~curvenet_client.errors.TransportError`. Everything else raises the
:class:`~curvenet_client.errors.CurvenetError` subclass of its code.
"""

from __future__ import annotations

import collections
import concurrent.futures
import http.client
import json
import os
import random
import socket
import threading
import time
import urllib.parse
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, TypeVar, overload

import numpy as np
import numpy.typing as npt

from ._version import __version__
from .errors import (
    BadInputError,
    PayloadTooLargeError,
    ProtocolError,
    TransportError,
    UnknownBindingError,
    error_from_response,
)
from .frames import (
    BlendShapeMode,
    Frame,
    FrameResult,
    decode_frames,
    decode_json_frame,
    encode_frames,
    frame_bytes,
    frame_json,
)
from .request import BindingRequest, as_request

__all__ = ["DEFAULT_URL", "Binding", "Client"]

#: Where ``curvenet serve`` listens by default.
DEFAULT_URL = "http://127.0.0.1:8720"

#: Statuses retried with back-off: the request was not done, or can be repeated.
RETRY_STATUSES = frozenset({429, 502, 503, 504})

Points = npt.NDArray[np.float32]
T = TypeVar("T")


@dataclass(frozen=True)
class _Answer:
    status: int
    headers: Mapping[str, str]
    body: bytes

    def json(self) -> Any:
        try:
            return json.loads(self.body)
        except ValueError as e:
            raise ProtocolError("protocol", f"the answer is not JSON: {e}", status=self.status) from None


def _retry_after(value: str | None) -> float | None:
    if value is None:
        return None
    try:
        seconds = float(value)
    except ValueError:
        return None  # an HTTP date: fall back to the client's own back-off
    return seconds if seconds >= 0 else None


class Client:
    """A connection to a ``curvenet serve`` service.

    Args:
        url: the service's base URL (``http://host:port``, optionally with a
            path prefix); default ``$CURVENET_URL``, else ``http://127.0.0.1:8720``.
        token: the bearer token; default ``$CURVENET_TOKEN`` (none when unset).
        timeout: seconds to wait to connect and for each read of an answer.
        retries: retries of a request after a connection failure or a 429,
            502, 503 or 504 answer (0: none).
        backoff: the first retry's wait in seconds; it doubles per retry.
        max_backoff: the longest wait between two tries, seconds.
        rebinds: how many times a frame request re-posts an evicted binding
            (404 ``unknown_binding``) before giving up.
        protocol: ``"binary"`` (the default: float32 arrays, 5x smaller than
            JSON) or ``"json"`` for frames.
        max_body_bytes: the largest request body a batch is made up to; the
            server's default ``--body-limit`` is 256 MiB. A batch refused with
            413 is split in halves and this limit lowered to match (and one
            refused with 422 ``limit_exceeded``, too large an answer or too
            much memory, is split and ``max_batch_frames`` lowered).
        max_batch_frames: the most frames in one ``frames:batch`` request.

    The client keeps one keep-alive connection per thread; it may be shared
    by threads. ``with Client(...) as c:`` closes the connections at the end.

    ``stats`` counts what the client did on its own: ``requests`` (HTTP
    exchanges, tries included), ``retries``, ``retry:<status>`` or
    ``retry:connection`` per cause, ``stale_connections`` (a kept-alive
    connection found closed: retried at once on a new one, not counted as a
    retry), ``rebinds`` (evicted bindings re-posted) and ``batch_splits``
    (batches split after a 413 or a 422 ``limit_exceeded``).
    """

    def __init__(
        self,
        url: str | None = None,
        token: str | None = None,
        *,
        timeout: float = 60.0,
        retries: int = 6,
        backoff: float = 0.25,
        max_backoff: float = 10.0,
        rebinds: int = 3,
        protocol: Literal["binary", "json"] = "binary",
        max_body_bytes: int = 64 << 20,
        max_batch_frames: int = 64,
    ) -> None:
        url = url if url is not None else os.environ.get("CURVENET_URL") or DEFAULT_URL
        parsed = urllib.parse.urlsplit(url)
        if parsed.scheme not in ("http", "https") or not parsed.hostname:
            raise ValueError(f"{url!r} is not an http:// or https:// URL")
        if protocol not in ("binary", "json"):
            raise ValueError(f"protocol must be 'binary' or 'json', not {protocol!r}")
        for name, value in (("retries", retries), ("rebinds", rebinds)):
            if value < 0:
                raise ValueError(f"{name} must not be negative, got {value}")
        if max_body_bytes < 1 or max_batch_frames < 1:
            raise ValueError("max_body_bytes and max_batch_frames must be positive")
        self.url = url.rstrip("/")
        self.token = token if token is not None else os.environ.get("CURVENET_TOKEN") or None
        self.timeout = timeout
        self.retries = retries
        self.backoff = backoff
        self.max_backoff = max_backoff
        self.rebinds = rebinds
        self.protocol = protocol
        self.max_body_bytes = max_body_bytes
        self.max_batch_frames = max_batch_frames
        self._https = parsed.scheme == "https"
        self._host = parsed.hostname
        self._port = parsed.port
        self._prefix = parsed.path.rstrip("/")
        self._local = threading.local()
        self._connections: list[http.client.HTTPConnection] = []
        self._lock = threading.Lock()
        self.stats: collections.Counter[str] = collections.Counter()

    def _count(self, *keys: str) -> None:
        with self._lock:
            self.stats.update(keys)

    # ------------------------------------------------------------------ connections

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def close(self) -> None:
        """Closes every connection this client opened (a later request opens a new one)."""
        with self._lock:
            connections, self._connections = self._connections, []
        for c in connections:
            c.close()

    def __repr__(self) -> str:
        return f"Client({self.url!r}, protocol={self.protocol!r})"

    def _connection(self) -> http.client.HTTPConnection:
        conn: http.client.HTTPConnection | None = getattr(self._local, "conn", None)
        if conn is None:
            if self._https:
                conn = http.client.HTTPSConnection(self._host, self._port, timeout=self.timeout)
            else:
                conn = http.client.HTTPConnection(self._host, self._port, timeout=self.timeout)
            self._local.conn = conn
            with self._lock:
                self._connections.append(conn)
        return conn

    def _drop_connection(self) -> None:
        conn: http.client.HTTPConnection | None = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None
            with self._lock:
                if conn in self._connections:
                    self._connections.remove(conn)

    def _headers(self, content_type: str | None, body: bytes | None) -> dict[str, str]:
        headers = {"User-Agent": f"curvenet-client/{__version__}", "Accept": "application/json"}
        if content_type is not None:
            headers["Content-Type"] = content_type
            if content_type == "application/octet-stream":
                headers["Accept"] = "application/octet-stream, application/json"
        if body is not None:
            headers["Content-Length"] = str(len(body))
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        return headers

    def _send_once(self, method: str, path: str, body: bytes | None, content_type: str | None) -> _Answer:
        """One try on this thread's connection. Raises OSError or
        http.client.HTTPException when no answer came."""
        conn = self._connection()
        self._local.reused = conn.sock is not None
        self._count("requests")
        try:
            try:
                conn.request(method, self._prefix + path, body=body, headers=self._headers(content_type, body))
            except (BrokenPipeError, ConnectionResetError):
                # The server may answer before reading the whole body (413 on
                # the declared Content-Length) and close: read that answer if it is there.
                pass
            resp = conn.getresponse()
            data = resp.read()
        except BaseException:
            self._drop_connection()
            raise
        headers = {k.lower(): v for k, v in resp.getheaders()}
        if resp.will_close:
            self._drop_connection()
        return _Answer(resp.status, headers, data)

    def _delay(self, attempt: int, retry_after: float | None) -> float:
        """Seconds before retry ``attempt + 1``: ``backoff * 2**attempt`` less
        up to a quarter, at least ``Retry-After`` plus up to a quarter (so
        that clients told the same delay do not return in step), at most
        ``max_backoff``."""
        delay = self.backoff * 2.0**attempt * (1.0 - 0.25 * random.random())
        if retry_after is not None:
            delay = max(delay, retry_after * (1.0 + 0.25 * random.random()))
        return min(delay, self.max_backoff)

    def _request(
        self,
        method: str,
        path: str,
        body: bytes | None = None,
        content_type: str | None = None,
    ) -> _Answer:
        """Sends a request with the retry policy; returns a 2xx answer or raises."""
        attempt = 0
        stale_retried = False
        while True:
            try:
                answer = self._send_once(method, path, body, content_type)
            except (TimeoutError, socket.timeout) as e:
                raise TransportError(
                    "transport", f"{method} {path}: no answer within {self.timeout} s (timeout): {e}"
                ) from e
            except (OSError, http.client.HTTPException) as e:
                if (
                    getattr(self._local, "reused", False)
                    and isinstance(e, (ConnectionResetError, BrokenPipeError, http.client.RemoteDisconnected))
                    and not stale_retried
                ):
                    # A kept-alive connection the server had closed (idle, or
                    # restarted): try once more on a new one, at once.
                    stale_retried = True
                    self._count("stale_connections")
                    continue
                if attempt >= self.retries:
                    raise TransportError(
                        "transport",
                        f"{method} {self.url}{path}: no answer after {attempt + 1} tries: {type(e).__name__}: {e}",
                    ) from e
                self._count("retries", "retry:connection")
                time.sleep(self._delay(attempt, None))
                attempt += 1
                continue
            if 200 <= answer.status < 300:
                return answer
            err = error_from_response(
                answer.status,
                answer.body,
                request_id=answer.headers.get("x-request-id"),
                retry_after=_retry_after(answer.headers.get("retry-after")),
            )
            if answer.status in RETRY_STATUSES and attempt < self.retries:
                self._count("retries", f"retry:{answer.status}")
                time.sleep(self._delay(attempt, err.retry_after))
                attempt += 1
                continue
            raise err

    def _json(self, method: str, path: str, doc: Any | None = None, *, raw: bytes | None = None) -> Any:
        body = raw if raw is not None else (None if doc is None else json.dumps(doc).encode())
        return self._request(method, path, body, "application/json" if body is not None else None).json()

    # ------------------------------------------------------------------ the API

    def bind(self, request: BindingRequest | Mapping[str, Any]) -> Binding:
        """Binds a mesh to its curvenets (``POST /v1/bindings``), or finds the
        binding the server already has. Returns a :class:`Binding` holding the
        id and the request, so that frames survive eviction and restarts."""
        req = as_request(request)
        body = req.to_bytes()
        info = self._json("POST", "/v1/bindings", raw=body)
        return Binding(self, req, body, info)

    def get_binding(self, binding_id: str) -> dict[str, Any]:
        """The ``BindingResponse`` of a cached binding (raises
        :class:`~curvenet_client.errors.UnknownBindingError` when it is not cached)."""
        info: dict[str, Any] = self._json("GET", f"/v1/bindings/{urllib.parse.quote(binding_id)}")
        return info

    def delete_binding(self, binding_id: str) -> bool:
        """Drops a binding from the server's cache; ``False`` when it was not cached."""
        try:
            self._request("DELETE", f"/v1/bindings/{urllib.parse.quote(binding_id)}")
        except UnknownBindingError:
            return False
        return True

    def health(self) -> bool:
        """``GET /healthz``: whether the process answers (no token needed).
        One try, no retries: a health check answers now or not at all."""
        try:
            answer = self._send_once("GET", "/healthz", None, None)
        except (OSError, http.client.HTTPException):
            return False
        return answer.status == 200

    def ready(self) -> bool:
        """``GET /readyz``: whether the server accepts work (not draining).
        Not retried: a draining server answers 503 at once."""
        try:
            answer = self._send_once("GET", "/readyz", None, None)
        except (OSError, http.client.HTTPException):
            return False
        return answer.status == 200

    def openapi(self) -> dict[str, Any]:
        """The service's OpenAPI 3.1 description."""
        doc: dict[str, Any] = self._json("GET", "/openapi.json")
        return doc

    def server_version(self) -> str:
        """The service's version (``info.version`` of its OpenAPI description)."""
        version = self.openapi().get("info", {}).get("version")
        if not isinstance(version, str):
            raise ProtocolError("protocol", "/openapi.json has no info.version")
        return version

    def bake(self, stage: str, output: str, frames: str | None = None) -> dict[str, Any]:
        """``POST /v1/bake``: the server bakes a stage on its own file system
        (both paths inside its ``--bake-root``s). Returns ``{stage, output, elapsed_ms,
        warnings}``, ``warnings`` the bake's warnings as ``curvenet bake`` prints them
        (a list of strings; empty when there were none)."""
        doc: dict[str, Any] = {"stage": stage, "output": output}
        if frames is not None:
            doc["frames"] = frames
        answer: dict[str, Any] = self._json("POST", "/v1/bake", doc)
        return answer

    # ------------------------------------------------------------------ frames

    def _post_frames(self, binding_id: str, frames: Sequence[Frame], gradients: bool, batch: bool) -> list[FrameResult]:
        results = self._post_frames_once(binding_id, frames, gradients, batch)
        if len(results) != len(frames):
            raise ProtocolError("protocol", f"{len(frames)} frames were sent but {len(results)} came back", status=200)
        return results

    def _post_frames_once(
        self, binding_id: str, frames: Sequence[Frame], gradients: bool, batch: bool
    ) -> list[FrameResult]:
        path = f"/v1/bindings/{binding_id}/frames" + (":batch" if batch else "")
        if self.protocol == "binary":
            body = encode_frames(frames, gradients=gradients, batch=batch)
            answer = self._request("POST", path, body, "application/octet-stream")
            if not answer.headers.get("content-type", "").startswith("application/octet-stream"):
                raise ProtocolError(
                    "protocol", f"expected a binary answer, got {answer.headers.get('content-type')!r}", status=200
                )
            return decode_frames(answer.body, batch=batch)
        if batch:
            doc: Any = {"frames": [frame_json(f, gradients=gradients) for f in frames]}
        else:
            doc = frame_json(frames[0], gradients=gradients)
        answer_doc = self._json("POST", path, doc)
        if batch:
            if not isinstance(answer_doc, dict) or not isinstance(answer_doc.get("frames"), list):
                raise ProtocolError("protocol", "a batch answer must be {frames: [...]}")
            return [decode_json_frame(d, f"frames[{i}]") for i, d in enumerate(answer_doc["frames"])]
        return [decode_json_frame(answer_doc)]

    def _body_estimate(self, frame: Frame) -> int:
        """Bytes a frame adds to a batch body (JSON numbers take ~20 bytes, not 4)."""
        n = frame_bytes(frame)
        return 256 + (n if self.protocol == "binary" else 6 * n)


def _as_frame(frame: Frame | Mapping[str, Any]) -> Frame:
    if isinstance(frame, Frame):
        return frame
    if isinstance(frame, Mapping):
        unknown = set(frame) - {
            "posed",
            "rest",
            "blend_shape_weights",
            "blend_shape_mode",
            "topology_hash",
            "adjustments",
            "orientations",
            "rest_cage",
            "posed_cage_offsets",
        }
        if unknown:
            raise ValueError(f"unknown frame fields {sorted(unknown)}")
        return Frame(**frame)
    raise TypeError(f"expected a Frame or a mapping, not {type(frame).__name__}")


class Binding:
    """A binding on the server: its id, the request that made it and the
    server's description (``info``: vertices, control points per curvenet,
    blend shapes, topology hash, stats, timings, warnings).

    Frames sent through it survive the binding's eviction and server restarts:
    a 404 ``unknown_binding`` re-posts the same request (same content, same
    id) and repeats the frame. Safe to use from several threads; concurrent
    frames that meet the eviction re-post it once.
    """

    def __init__(self, client: Client, request: BindingRequest, body: bytes, info: Mapping[str, Any]) -> None:
        self.client = client
        self.request = request
        self._body = body
        self._lock = threading.Lock()
        self._generation = 0
        self.rebound = 0
        self._set_info(info)

    def _set_info(self, info: Mapping[str, Any]) -> None:
        if not isinstance(info, Mapping) or not isinstance(info.get("binding_id"), str):
            raise ProtocolError("protocol", "the binding answer has no binding_id")
        self.info: dict[str, Any] = dict(info)
        self.id: str = info["binding_id"]

    @property
    def vertices(self) -> int:
        return int(self.info.get("vertices", self.request.vertices))

    @property
    def topology_hash(self) -> str:
        return str(self.info.get("topology_hash", ""))

    def __repr__(self) -> str:
        return f"Binding({self.id[:12]}..., vertices={self.vertices})"

    def _rebind(self, generation: int) -> None:
        with self._lock:
            if self._generation != generation:
                return  # another thread re-posted it meanwhile
            info = self.client._json("POST", "/v1/bindings", raw=self._body)
            self._set_info(info)
            self._generation += 1
            self.rebound += 1
            self.client._count("rebinds")

    def _with_rebind(self, send: Callable[[str], T]) -> T:
        tries = 0
        while True:
            generation, binding_id = self._generation, self.id
            try:
                return send(binding_id)
            except UnknownBindingError:
                if tries >= self.client.rebinds:
                    raise
                tries += 1
                self._rebind(generation)

    def solve(self, frames: Sequence[Frame | Mapping[str, Any]], *, gradients: bool = False) -> list[FrameResult]:
        """Deforms ``frames`` in one request (one frame: ``/frames``; more:
        ``/frames:batch``), re-posting the binding when it was evicted.
        Returns :class:`~curvenet_client.frames.FrameResult` s with ``solve_ms``."""
        fs = [_as_frame(f) for f in frames]
        if not fs:
            return []
        batch = len(fs) > 1
        return self._with_rebind(lambda bid: self.client._post_frames(bid, fs, gradients, batch))

    @overload
    def deform(
        self,
        posed: Sequence[npt.ArrayLike | None] | None = None,
        rest: npt.ArrayLike | None = None,
        blend_shape_weights: npt.ArrayLike | None = None,
        gradients: Literal[False] = False,
        *,
        blend_shape_mode: BlendShapeMode = "after",
        topology_hash: str | None = None,
    ) -> Points: ...

    @overload
    def deform(
        self,
        posed: Sequence[npt.ArrayLike | None] | None = None,
        rest: npt.ArrayLike | None = None,
        blend_shape_weights: npt.ArrayLike | None = None,
        *,
        gradients: Literal[True],
        blend_shape_mode: BlendShapeMode = "after",
        topology_hash: str | None = None,
    ) -> tuple[Points, Points]: ...

    def deform(
        self,
        posed: Sequence[npt.ArrayLike | None] | None = None,
        rest: npt.ArrayLike | None = None,
        blend_shape_weights: npt.ArrayLike | None = None,
        gradients: bool = False,
        *,
        blend_shape_mode: BlendShapeMode = "after",
        topology_hash: str | None = None,
    ) -> Points | tuple[Points, Points]:
        """Deforms one frame.

        Args:
            posed: one ``(P, 3)`` pool per curvenet, or ``None`` for one not
                articulated; ``None``: none articulated.
            rest: the frame's rest pose ``(V, 3)``; ``None``: the projection pose.
            blend_shape_weights: one per blend shape; ``None``: all zero.
            gradients: also return the per-vertex deformation gradients.

        Returns:
            the deformed points ``(V, 3)`` float32, or ``(points, gradients)``
            with gradients ``(V, 3, 3)`` when ``gradients`` is true.
        """
        frame = Frame(posed, rest, blend_shape_weights, blend_shape_mode, topology_hash)
        (result,) = self.solve([frame], gradients=gradients)
        return _output(result, gradients)

    @overload
    def deform_many(
        self, frames: Iterable[Frame | Mapping[str, Any]], *, gradients: Literal[False] = False
    ) -> list[Points]: ...

    @overload
    def deform_many(
        self, frames: Iterable[Frame | Mapping[str, Any]], *, gradients: Literal[True]
    ) -> list[tuple[Points, Points]]: ...

    def deform_many(
        self, frames: Iterable[Frame | Mapping[str, Any]], *, gradients: bool = False
    ) -> list[Points] | list[tuple[Points, Points]]:
        """Deforms many frames through ``frames:batch``, in chunks of at most
        ``client.max_batch_frames`` frames and ``client.max_body_bytes`` bytes,
        one chunk after another; results in input order."""
        out: list[Any] = list(self._results(frames, gradients, in_flight=1, frames_per_request=None))
        return out

    @overload
    def deform_iter(
        self,
        frames: Iterable[Frame | Mapping[str, Any]],
        *,
        gradients: Literal[False] = False,
        in_flight: int = 4,
        frames_per_request: int = 1,
    ) -> Iterator[Points]: ...

    @overload
    def deform_iter(
        self,
        frames: Iterable[Frame | Mapping[str, Any]],
        *,
        gradients: Literal[True],
        in_flight: int = 4,
        frames_per_request: int = 1,
    ) -> Iterator[tuple[Points, Points]]: ...

    def deform_iter(
        self,
        frames: Iterable[Frame | Mapping[str, Any]],
        *,
        gradients: bool = False,
        in_flight: int = 4,
        frames_per_request: int = 1,
    ) -> Iterator[Points] | Iterator[tuple[Points, Points]]:
        """Streams a shot: yields each frame's result in input order while up
        to ``in_flight`` requests (of ``frames_per_request`` frames each) are
        solving on the server, from a pool of ``in_flight`` threads.

        ``frames`` is read lazily, on the calling thread, only as far ahead as
        the requests in flight need: a generator reading a stage frame by
        frame holds at most ``in_flight * frames_per_request`` frames' inputs.
        Stopping early (``break``) waits for the requests in flight and drops
        their results. The first failing request raises its error when its
        turn comes.
        """
        if in_flight < 1 or frames_per_request < 1:
            raise ValueError("in_flight and frames_per_request must be at least 1")
        return self._results(frames, gradients, in_flight=in_flight, frames_per_request=frames_per_request)

    def _chunks(self, frames: Iterable[Frame | Mapping[str, Any]], frames_per_request: int | None) -> Iterator[list[Frame]]:
        """Groups frames into requests: ``frames_per_request`` each, or (None)
        as many as fit ``max_batch_frames`` and ``max_body_bytes``."""
        chunk: list[Frame] = []
        size = 0
        for f in frames:
            frame = _as_frame(f)
            if frames_per_request is not None:
                chunk.append(frame)
                if len(chunk) == frames_per_request:
                    yield chunk
                    chunk = []
                continue
            n = self.client._body_estimate(frame)
            if chunk and (len(chunk) >= self.client.max_batch_frames or size + n > self.client.max_body_bytes):
                yield chunk
                chunk, size = [], 0
            chunk.append(frame)
            size += n
        if chunk:
            yield chunk

    def _solve_split(self, chunk: list[Frame], gradients: bool) -> list[FrameResult]:
        """A chunk's request; a batch refused as too large (413: its body;
        422 ``limit_exceeded``: its answer or its memory, ``--max-batch-bytes``
        or ``--max-batch-memory``) is split in halves, and the client's body
        budget or frames per batch lowered below what was refused."""
        try:
            return self.solve(chunk, gradients=gradients)
        except PayloadTooLargeError:
            if len(chunk) == 1:
                raise
            self.client._count("batch_splits")
            refused = sum(self.client._body_estimate(f) for f in chunk)
            self.client.max_body_bytes = max(1, min(self.client.max_body_bytes, refused // 2))
        except BadInputError as e:
            if e.code != "limit_exceeded" or len(chunk) == 1:
                raise
            self.client._count("batch_splits")
            self.client.max_batch_frames = max(1, min(self.client.max_batch_frames, len(chunk) // 2))
        half = len(chunk) // 2
        return self._solve_split(chunk[:half], gradients) + self._solve_split(chunk[half:], gradients)

    def _results(
        self,
        frames: Iterable[Frame | Mapping[str, Any]],
        gradients: bool,
        *,
        in_flight: int,
        frames_per_request: int | None,
    ) -> Iterator[Any]:
        chunks = self._chunks(frames, frames_per_request)
        if in_flight == 1:
            for chunk in chunks:
                for r in self._solve_split(chunk, gradients):
                    yield _output(r, gradients)
            return
        pending: collections.deque[concurrent.futures.Future[list[FrameResult]]] = collections.deque()
        pool = concurrent.futures.ThreadPoolExecutor(max_workers=in_flight, thread_name_prefix="curvenet")
        try:
            for chunk in chunks:
                if len(pending) >= in_flight:
                    for r in pending.popleft().result():
                        yield _output(r, gradients)
                pending.append(pool.submit(self._solve_split, chunk, gradients))
            while pending:
                for r in pending.popleft().result():
                    yield _output(r, gradients)
        finally:
            for f in pending:
                f.cancel()
            pool.shutdown(wait=True)


def _output(result: FrameResult, gradients: bool) -> Points | tuple[Points, Points]:
    if not gradients:
        return result.points
    if result.gradients is None:
        raise ProtocolError("protocol", "gradients were asked for but the answer has none")
    return result.points, result.gradients
