"""``python -m curvenet_client bake-remote STAGE --out OUT [--url URL] [--frames A-B]``:
bakes a shot through a running service.

The client reads the stage with usd-core (every curvenet-deformed mesh, its
binding request and each frame's posed pools, rest pose and blend-shape
weights, as ``curvenet bake`` reads them), binds each mesh on the service,
streams the frames through it (``--in-flight`` requests at once; the service
solves), and writes the layer ``curvenet bake`` writes: ``over`` opinions with
the deformed ``points`` time samples, ``startTimeCode``/``endTimeCode`` of the
frames, and the bake's ``doc`` (naming the service's curvenet version and
STAGE as given).

Writers:

- default: usd-core writes the layer. Same content as ``curvenet bake``'s
  layer (the same prims and ``over`` specifiers, the same float32 points bit
  for bit at every frame, the same metadata), not the same bytes: usd-core
  and the bake's Rust writer format files differently.
- ``--stitch-with CURVENET``: the usd-core layer is then passed through
  ``CURVENET stitch`` (the bake's own writer, which rewrites a bake layer as a
  whole-range bake writes it), giving the same bytes as ``curvenet bake``.
  Needs the ``curvenet`` binary on this machine.

Exit status: 0 success; 2 bad input, not worth retrying (a stage that breaks
the contract, a frame or binding the service refuses, a wrong token, a bad
command); 75 worth retrying (the service unreachable or saturated after the
retries, an I/O failure writing OUT); 1 anything else (a server bug, an answer
the client cannot read).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from ._version import __version__
from .client import Client
from .errors import (
    BadInputError,
    CurvenetError,
    NotFoundError,
    SaturatedError,
    TransportError,
    UnauthorizedError,
)

EXIT_INPUT = 2
EXIT_RETRY = 75
EXIT_OTHER = 1


class CommandError(Exception):
    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


def parse_frames(text: str) -> tuple[int, int]:
    """``A-B`` or ``A`` (inclusive integer time codes, either may be
    negative: ``-5--1``), as ``curvenet bake --frames`` takes them."""
    s = "".join(text.split())
    split = next((i for i, c in enumerate(s) if c == "-" and i > 0 and s[i - 1].isdigit()), None)
    a, b = (s[:split], s[split + 1 :]) if split is not None else (s, s)
    try:
        first, last = int(a), int(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not A-B or A (integer frames)") from None
    if first > last:
        raise argparse.ArgumentTypeError(f"{first}-{last} is empty: the first frame must not be after the last")
    if last - first >= 1_000_000:
        raise argparse.ArgumentTypeError(f"{first}-{last} is more than 1000000 frames")
    return first, last


class Progress:
    """On a terminal: one line of frames done, frames per second and ETA,
    rewritten in place; otherwise nothing until the summary."""

    def __init__(self, total: int, stream: TextIO, enabled: bool) -> None:
        self.total = total
        self.done = 0
        self.stream = stream
        self.enabled = enabled and stream.isatty()
        self.start = time.monotonic()
        self._last = 0.0

    def tick(self, n: int = 1) -> None:
        self.done += n
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        elapsed = max(now - self.start, 1e-9)
        rate = self.done / elapsed
        eta = (self.total - self.done) / rate if rate > 0 else 0.0
        width = 30
        filled = int(width * self.done / max(self.total, 1))
        bar = "#" * filled + "-" * (width - filled)
        self.stream.write(f"\r[{bar}] {self.done}/{self.total} frames, {rate:.1f}/s, ETA {eta:.0f} s ")
        self.stream.flush()

    def finish(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def bake_remote(args: argparse.Namespace) -> int:
    from . import usd  # needs usd-core: imported here so the rest of the command line works without it

    started = time.monotonic()
    out = Path(args.out)
    if out.suffix.lower() not in (".usda", ".usdc"):
        raise CommandError(f"{out}: the output must end in .usda or .usdc", EXIT_INPUT)
    if not out.parent.is_dir():
        raise CommandError(f"cannot write {out}: directory {out.parent} does not exist", EXIT_RETRY)
    stitcher = None
    if args.stitch_with is not None:
        stitcher = shutil.which(args.stitch_with)
        if stitcher is None:
            raise CommandError(f"--stitch-with {args.stitch_with}: no such executable", EXIT_INPUT)
    try:
        stage = usd.open_stage(args.stage)
        paths = usd.deformed_meshes(stage)
        if not paths:
            raise CommandError(
                f"{args.stage}: no Mesh has rel curvenet:curvenets, so there is nothing to bake", EXIT_INPUT
            )
        meshes = [usd.StageMesh(stage, p) for p in paths]
        if args.frames is not None:
            times = [float(t) for t in range(args.frames[0], args.frames[1] + 1)]
        else:
            times = usd.frame_range(stage, meshes)
    except (usd.UsdContractError, FileNotFoundError) as e:
        raise CommandError(str(e), EXIT_INPUT) from None

    client = Client(args.url, args.token, timeout=args.timeout, retries=args.retries)
    with client:
        version = client.server_version()
        progress = Progress(len(times) * len(meshes), sys.stderr, not args.quiet)
        baked: dict[str, list[tuple[float, object]]] = {}
        t_bind = 0.0
        for mesh in meshes:
            t0 = time.monotonic()
            binding = client.bind(mesh.request)
            t_bind += time.monotonic() - t0
            for w in binding.info.get("warnings", []):
                print(f"curvenet-client: warning: {mesh.path}: {w.get('message', w)}", file=sys.stderr)
            try:
                frames = (mesh.frame(t) for t in times)  # read lazily, as the requests go out
                samples: list[tuple[float, object]] = []
                for t, points in zip(times, binding.deform_iter(frames, in_flight=args.in_flight)):
                    samples.append((t, points))
                    progress.tick()
            except usd.UsdContractError as e:
                raise CommandError(str(e), EXIT_INPUT) from None
            except CurvenetError as e:
                e.args = (f"{mesh.path}: {e.args[0]}",)
                raise
            baked[mesh.path] = samples
        progress.finish()

    doc = (
        f"Baked by curvenet {version} (`curvenet bake`) from {args.stage}: the deformed points of "
        f"{', '.join(m.path for m in meshes)} from startTimeCode to endTimeCode, as over opinions only. "
        "Sublayer above (stronger than) the input."
    )
    time_range = (times[0], times[-1])
    try:
        if stitcher is None:
            usd.write_bake_layer(out, baked, doc=doc, time_range=time_range)  # type: ignore[arg-type]
        else:
            with tempfile.TemporaryDirectory(prefix=".curvenet-client-", dir=out.parent) as tmp:
                # A text intermediate: curvenet releases before the stitch
                # took usd-core's .usdc (prims whose `over` specifier is left
                # to Sdf's fallback) refused it.
                layer = Path(tmp) / "remote.usda"
                usd.write_bake_layer(layer, baked, doc=doc, time_range=time_range)  # type: ignore[arg-type]
                r = subprocess.run(
                    [stitcher, "stitch", str(layer), "--out", str(out), "--quiet"],
                    capture_output=True,
                    text=True,
                )
                if r.returncode != 0:
                    raise CommandError(
                        f"{args.stitch_with} stitch failed (exit {r.returncode}): {r.stderr.strip()}",
                        EXIT_RETRY if r.returncode == 75 else EXIT_OTHER,
                    )
    except OSError as e:
        raise CommandError(f"cannot write {out}: {e}", EXIT_RETRY) from None
    if not args.quiet:
        n = len(times)
        print(
            f"curvenet-client: baked {len(meshes)} mesh{'es' if len(meshes) != 1 else ''} x {n} "
            f"frame{'s' if n != 1 else ''} ({times[0]:g}-{times[-1]:g}) through {client.url} to {out} in "
            f"{time.monotonic() - started:.2f} s (bind {t_bind * 1e3:.0f} ms"
            f"{', written by ' + args.stitch_with + ' stitch' if stitcher else ''})",
            file=sys.stderr,
        )
    return 0


def exit_status(e: CurvenetError) -> int:
    if isinstance(e, (TransportError, SaturatedError)):
        return EXIT_RETRY
    if isinstance(e, (BadInputError, NotFoundError, UnauthorizedError)):
        return EXIT_INPUT
    return EXIT_OTHER


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m curvenet_client", description="The curvenet service's Python client."
    )
    parser.add_argument("--version", action="version", version=f"curvenet-client {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    bake = sub.add_parser(
        "bake-remote",
        help="bake a shot through a running service",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    bake.add_argument("stage", help="the shot stage (.usda, .usdc, .usdz), read here with usd-core")
    bake.add_argument("--out", "-o", required=True, help="the layer to write: .usda or .usdc, by its extension")
    bake.add_argument("--url", default=None, help="the service (default: $CURVENET_URL, else http://127.0.0.1:8720)")
    bake.add_argument("--token", default=None, help="bearer token (prefer $CURVENET_TOKEN: flags show in ps)")
    bake.add_argument(
        "--frames", type=parse_frames, default=None, metavar="A-B",
        help="frames to bake, inclusive (default: the stage's startTimeCode-endTimeCode, else its time samples)",
    )
    bake.add_argument("--in-flight", type=int, default=4, help="frame requests solving at once (default 4)")
    bake.add_argument("--timeout", type=float, default=60.0, help="seconds to wait for an answer (default 60)")
    bake.add_argument("--retries", type=int, default=6, help="retries after a 503 or a connection failure (default 6)")
    bake.add_argument(
        "--stitch-with", metavar="CURVENET", default=None,
        help="write through `CURVENET stitch` (the bake's writer): the same bytes as `curvenet bake`",
    )
    bake.add_argument("--quiet", "-q", action="store_true", help="no progress bar and no summary")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.in_flight < 1:
        print("curvenet-client: --in-flight must be at least 1", file=sys.stderr)
        return EXIT_INPUT
    try:
        return bake_remote(args)
    except CommandError as e:
        print(f"curvenet-client: {e}", file=sys.stderr)
        return e.status
    except CurvenetError as e:
        print(f"curvenet-client: {e}", file=sys.stderr)
        return exit_status(e)
    except ImportError as e:
        print(f"curvenet-client: bake-remote needs usd-core (pip install 'curvenet-client[usd]'): {e}", file=sys.stderr)
        return EXIT_INPUT


if __name__ == "__main__":
    sys.exit(main())
