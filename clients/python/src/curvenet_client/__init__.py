"""curvenet-client: the Python client of the curvenet deformer service
(``curvenet serve``).

>>> from curvenet_client import Client
>>> client = Client("http://127.0.0.1:8720")           # doctest: +SKIP
>>> binding = client.bind(request)                     # doctest: +SKIP
>>> points = binding.deform(posed=[pool])              # doctest: +SKIP

The USD helpers are in :mod:`curvenet_client.usd` (needs the ``usd`` extra,
``pip install 'curvenet-client[usd]'``); the shot bake through a service is
``python -m curvenet_client bake-remote``. See the package's README.
"""

from ._version import __version__
from .client import DEFAULT_URL, Binding, Client
from .errors import (
    BadInputError,
    CurvenetError,
    NotFoundError,
    PayloadTooLargeError,
    ProtocolError,
    SaturatedError,
    ServerError,
    TransportError,
    UnauthorizedError,
    UnknownBindingError,
)
from .frames import Frame, FrameResult
from .request import BindingOptions, BindingRequest, BlendShape, Cage, CurvenetSpec, Inbetween

__all__ = [
    "DEFAULT_URL",
    "BadInputError",
    "Binding",
    "BindingOptions",
    "BindingRequest",
    "BlendShape",
    "Cage",
    "Client",
    "CurvenetError",
    "CurvenetSpec",
    "Frame",
    "FrameResult",
    "Inbetween",
    "NotFoundError",
    "PayloadTooLargeError",
    "ProtocolError",
    "SaturatedError",
    "ServerError",
    "TransportError",
    "UnauthorizedError",
    "UnknownBindingError",
    "__version__",
]
