"""Typed errors: every error answer of the service becomes a
:class:`CurvenetError` subclass carrying the service's ``code``, ``message``
and ``details``.

The service answers errors as ``{"code": ..., "message": ..., "details": {...}}``
(``details`` optional). A known code picks its class from :data:`CODE_FAMILIES`;
a code this client does not know yet picks it from the HTTP status family, so a
newer server never makes the client fail to raise something sensible.

Families::

    CurvenetError
    ├── BadInputError        400, 405, 409, 413, 415, 422: fix the request; a retry fails the same way
    │   └── PayloadTooLargeError   413 payload_too_large
    ├── NotFoundError        404
    │   └── UnknownBindingError    404 unknown_binding (the client re-posts the binding itself)
    ├── UnauthorizedError    401, 403: a missing or wrong token, a path outside the bake roots
    ├── SaturatedError       503 (and 429): raised once the retries are used up
    ├── ServerError          500, 507 and other 5xx: the server's fault or capacity
    ├── TransportError       no HTTP answer at all (refused, reset, timed out), after the retries
    └── ProtocolError        an answer this client cannot read (bad framing, not JSON)

``TransportError`` and ``ProtocolError`` are the client's own: their ``code`` is
``"transport"`` or ``"protocol"`` and ``status`` is ``None`` (for a protocol error
with an HTTP answer, the status of that answer).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

__all__ = [
    "CODE_FAMILIES",
    "BadInputError",
    "CurvenetError",
    "NotFoundError",
    "PayloadTooLargeError",
    "ProtocolError",
    "SaturatedError",
    "ServerError",
    "TransportError",
    "UnauthorizedError",
    "UnknownBindingError",
    "error_from_response",
]


class CurvenetError(Exception):
    """An error answered by the service (or, for the two client-side
    subclasses, met on the way to it).

    Attributes:
        code: the service's stable snake_case code (``count_mismatch``,
            ``unknown_binding``, ...), or ``http_<status>`` when the answer
            carried no code, or ``transport``/``protocol`` for client-side errors.
        message: the service's message (names the offending array and index).
        status: the HTTP status, or ``None`` when there was no answer.
        details: the error body's ``details`` object (``{}`` when absent), e.g.
            ``{"curvenet": 0, "spline": 3}``.
        request_id: the answer's ``x-request-id`` (the server logs under it).
        retry_after: the answer's ``Retry-After`` in seconds, when it had one.
    """

    def __init__(
        self,
        code: str,
        message: str,
        *,
        status: int | None = None,
        details: Mapping[str, Any] | None = None,
        request_id: str | None = None,
        retry_after: float | None = None,
    ) -> None:
        super().__init__(f"{code}: {message}" if status is None else f"{code} (HTTP {status}): {message}")
        self.code = code
        self.message = message
        self.status = status
        self.details: dict[str, Any] = dict(details) if details else {}
        self.request_id = request_id
        self.retry_after = retry_after


class BadInputError(CurvenetError):
    """The request is wrong (400, 405, 409, 413, 415, 422): malformed JSON or
    binary framing, counts that disagree, a non-finite number, an invalid mesh
    or curvenet, a binding that cannot be made. Not worth retrying."""


class PayloadTooLargeError(BadInputError):
    """413 ``payload_too_large``: the body is over the server's ``--body-limit``.
    Batches are split and retried by the client; a single frame this large is raised."""


class NotFoundError(CurvenetError):
    """404: no such binding, stage or route."""


class UnknownBindingError(NotFoundError):
    """404 ``unknown_binding``: the binding is not cached (evicted, or the server
    restarted). :class:`curvenet_client.Binding` re-posts its request and retries;
    this is raised only when that keeps failing."""


class UnauthorizedError(CurvenetError):
    """401 ``unauthorized`` (missing or wrong token) or 403 ``path_forbidden``."""


class SaturatedError(CurvenetError):
    """503 ``saturated``/``unavailable`` (or 429): the server is busy or a
    transient failure happened. Retried with back-off; raised when the retries
    are used up."""


class ServerError(CurvenetError):
    """500 ``internal`` (a bug: the server log has the details under
    ``request_id``), 507 ``cache_too_small``, or another 5xx."""


class TransportError(CurvenetError):
    """No HTTP answer: the connection was refused, reset or timed out. Retried
    with back-off (except timeouts); raised when the retries are used up."""


class ProtocolError(CurvenetError):
    """An answer this client cannot read: a binary frame whose framing is
    wrong, or a success answer that is not the expected JSON."""


#: The family of every code the service documents (server/README.md, "Errors").
CODE_FAMILIES: dict[str, type[CurvenetError]] = {
    "malformed_json": BadInputError,
    "malformed_binary": BadInputError,
    "unsupported_media_type": BadInputError,
    "count_mismatch": BadInputError,
    "non_finite": BadInputError,
    "index_out_of_range": BadInputError,
    "empty_input": BadInputError,
    "invalid_mesh": BadInputError,
    "invalid_curvenet": BadInputError,
    "invalid_parameter": BadInputError,
    "binding_failed": BadInputError,
    "degenerate_pose": BadInputError,
    "unsupported": BadInputError,
    "unknown_binding": UnknownBindingError,
    "topology_changed": BadInputError,
    "payload_too_large": PayloadTooLargeError,
    "cache_too_small": ServerError,
    "unauthorized": UnauthorizedError,
    "path_forbidden": UnauthorizedError,
    "stage_not_found": NotFoundError,
    "bake_failed": BadInputError,
    "not_found": NotFoundError,
    "method_not_allowed": BadInputError,
    "saturated": SaturatedError,
    "unavailable": SaturatedError,
    "internal": ServerError,
}


def family_of_status(status: int) -> type[CurvenetError]:
    """The class of an error with an unknown code, by its HTTP status."""
    if status == 413:
        return PayloadTooLargeError
    if status in (401, 403):
        return UnauthorizedError
    if status == 404:
        return NotFoundError
    if status in (429, 503):
        return SaturatedError
    if 400 <= status < 500:
        return BadInputError
    if status >= 500:
        return ServerError
    return ProtocolError  # an error body with a 1xx-3xx status: not an answer this client understands


def error_from_response(
    status: int,
    body: bytes,
    *,
    request_id: str | None = None,
    retry_after: float | None = None,
) -> CurvenetError:
    """The exception for an error answer: the class of its code (known codes),
    else of its status; ``details`` carried when the body has an object there.
    A body that is not the service's JSON (a proxy's HTML page) gives the code
    ``http_<status>`` and the start of the body as the message."""
    code: str | None = None
    message: str | None = None
    details: Mapping[str, Any] | None = None
    try:
        parsed = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        parsed = None
    if isinstance(parsed, dict):
        if isinstance(parsed.get("code"), str):
            code = parsed["code"]
        if isinstance(parsed.get("message"), str):
            message = parsed["message"]
        if isinstance(parsed.get("details"), dict):
            details = parsed["details"]
    if code is None:
        text = body[:500].decode("utf-8", "replace").strip()
        return family_of_status(status)(
            f"http_{status}",
            text or "the answer has no body",
            status=status,
            request_id=request_id,
            retry_after=retry_after,
        )
    cls = CODE_FAMILIES.get(code) or family_of_status(status)
    return cls(
        code,
        message if message is not None else "",
        status=status,
        details=details,
        request_id=request_id,
        retry_after=retry_after,
    )
