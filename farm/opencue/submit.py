#!/usr/bin/env python3
"""Submit a curvenet shot bake to OpenCue: a chunked bake layer and a stitch
layer that waits for all of it (README.md, "Farm").

    submit.py SHOT --output OUT.usdc --frames 1-240 [--chunk-size 96]
              [--curvenet /path/to/curvenet] [--show S --shot NAME --user U]
              [--store DIR|s3://bucket/prefix] [--cuebot HOST] [--print-spec]

The job, built with PyOutline and launched without the pycuerun wrapper
(`use_pycuerun=False`, so the farm hosts need only the curvenet binary):

* layer `bake`: range FIRST-LAST, chunk CHUNK; each frame of the layer runs
  `curvenet bake SHOT --frames #FRAME_START#-#FRAME_END#` into
  OUT.chunks/#FRAME_START#-#FRAME_END#.usdc (Cuebot replaces the tokens with
  the chunk's first and last frame), written atomically, the same bytes on
  every rerun.
* layer `bind` (with `--store`): one frame that binds every mesh once into
  the binding store (it bakes the first frame into a hidden scratch file and
  deletes it); `bake` then waits for it (LAYER_ON_LAYER) and every chunk
  runs with `--store`, reading the bindings instead of binding again.
* layer `stitch`: one frame, a LAYER_ON_LAYER dependency on `bake`; runs
  `curvenet stitch` over the chunk files of this job (listed explicitly, so
  stale chunks of another submission are never read) with `--frames
  FIRST-LAST` into OUT.

`--print-spec` prints the OpenCue job spec (XML, cjsl DTD) instead of
launching; launching needs a Cuebot (`--cuebot` or the usual opencue
config). Either way the chunk directory is created, so the bake tasks can
write into it.
"""

import argparse
import os
import re
import shlex
import sys

import outline
import outline.cuerun
from outline.modules.shell import Shell, ShellCommand

# Cuebot replaces these in a layer's command at dispatch: the first and the
# last frame of the chunk being run.
FRAME_START = "#FRAME_START#"
FRAME_END = "#FRAME_END#"
CHUNK_FRAMES = f"{FRAME_START}-{FRAME_END}"


def parse_frames(text):
    """`A-B` or `A` (either may be negative, as `curvenet bake --frames`) -> (A, B)."""
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?", text)
    if not m:
        raise ValueError(f"{text!r} is not a frame range (expected A-B or A)")
    first = int(m.group(1))
    last = int(m.group(2)) if m.group(2) is not None else first
    if first > last:
        raise ValueError(f"{text!r} is empty: the first frame must not be after the last")
    return first, last


def chunk_ranges(first, last, chunk_size):
    """The (first, last) frames of each task OpenCue dispatches for a layer
    with range FIRST-LAST and chunk CHUNK_SIZE: consecutive runs of
    CHUNK_SIZE frames, the last one shorter."""
    if chunk_size < 1:
        raise ValueError(f"chunk size {chunk_size} is not positive")
    return [(a, min(a + chunk_size - 1, last)) for a in range(first, last + 1, chunk_size)]


def chunk_dir(output):
    """Where the bake tasks write their chunks: OUTPUT.chunks beside OUTPUT."""
    return output + ".chunks"


def _command(argv):
    # The frame's command is one string; quote each argument so paths with
    # spaces survive the host's shell (the #...# tokens survive quoting).
    return " ".join(shlex.quote(str(a)) for a in argv)


def _nmtoken(text):
    # Job and layer names are NMTOKENs in the job spec DTD.
    return re.sub(r"[^A-Za-z0-9_.-]", "_", text) or "curvenet"


def build_outline(
    shot,
    output,
    first,
    last,
    chunk_size,
    curvenet="curvenet",
    name=None,
    show=None,
    shot_name=None,
    user=None,
    service=None,
    cores=None,
    memory=None,
    store=None,
):
    """The outline of one shot bake: layers `bake` (chunked) and `stitch`
    (depends on all of `bake`). SHOT and OUTPUT should be absolute paths
    on the farm's shared storage."""
    if first > last:
        raise ValueError(f"frames {first}-{last} are empty")
    stem = os.path.splitext(os.path.basename(output))[0]
    ol = outline.Outline(
        _nmtoken(name or f"curvenet_{stem}"),
        frame_range=f"{first}-{last}",
        shot=shot_name,
        show=show,
        user=user,
    )
    chunks = chunk_dir(output)
    layer_args = {}
    if service:
        layer_args["service"] = service
    if cores:
        layer_args["cores"] = cores
    if memory:
        layer_args["memory"] = memory
    store_args = ["--store", store] if store else []
    bake = Shell(
        "bake",
        command=_command(
            [curvenet, "bake", shot, "--out", f"{chunks}/{CHUNK_FRAMES}.usdc", "--frames", CHUNK_FRAMES, *store_args]
        ),
        range=f"{first}-{last}",
        chunk=chunk_size,
        **layer_args,
    )
    files = [f"{chunks}/{a}-{b}.usdc" for a, b in chunk_ranges(first, last, chunk_size)]
    stitch = ShellCommand(
        "stitch",
        command=_command([curvenet, "stitch", *files, "--frames", f"{first}-{last}", "--out", output]),
        **layer_args,
    )
    if store:
        scratch = f"{chunks}/.bind.usdc"
        bind = ShellCommand(
            "bind",
            command=_command(
                ["sh", "-c", 'set -e; "$0" bake "$1" --out "$2" --frames "$3" --store "$4" --quiet; rm -f -- "$2"',
                 curvenet, shot, scratch, str(first), store]
            ),
            **layer_args,
        )
        ol.add_layer(bind)
    ol.add_layer(bake)
    ol.add_layer(stitch)
    if store:
        bake.depend_all(bind)
    stitch.depend_all(bake)
    return ol


def serialize(ol):
    """The OpenCue job spec (XML) of an outline, commands unwrapped."""
    return outline.cuerun.OutlineLauncher(ol).serialize(use_pycuerun=False)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("shot_stage", metavar="SHOT", help="the shot stage to bake (.usda, .usdc, .usdz)")
    p.add_argument("--output", "-o", required=True, help="the stitched layer (.usda or .usdc)")
    p.add_argument("--frames", required=True, help="frames to bake: A-B (inclusive) or A")
    p.add_argument("--chunk-size", type=int, default=96, help="frames per bake task (default 96; README, Farm)")
    p.add_argument("--curvenet", default="curvenet", help="the curvenet command on the farm hosts")
    p.add_argument("--name", help="job name (default curvenet_<output stem>)")
    p.add_argument("--show", help="OpenCue show")
    p.add_argument("--shot", dest="shot_name", help="OpenCue shot name")
    p.add_argument("--user", help="OpenCue user")
    p.add_argument("--service", help="OpenCue service for both layers")
    p.add_argument("--cores", type=float, help="cores per task (default: the service's)")
    p.add_argument("--memory", help="memory per task, e.g. 4g (default: the service's)")
    p.add_argument("--store", help="a binding store on shared storage (a directory or s3://bucket/prefix): "
                   "a `bind` layer binds each mesh once and every chunk reads it")
    p.add_argument("--cuebot", help="Cuebot host to launch on")
    p.add_argument("--pause", action="store_true", help="launch the job paused")
    p.add_argument("--print-spec", action="store_true", help="print the job spec instead of launching")
    args = p.parse_args(argv)
    try:
        first, last = parse_frames(args.frames)
        if os.path.splitext(args.output)[1].lower() not in (".usda", ".usdc"):
            raise ValueError(f"{args.output}: the output must end in .usda or .usdc")
        # Farm hosts do not share this shell's working directory.
        shot, output = os.path.abspath(args.shot_stage), os.path.abspath(args.output)
        ol = build_outline(
            shot, output, first, last, args.chunk_size, curvenet=args.curvenet, name=args.name,
            show=args.show, shot_name=args.shot_name, user=args.user, service=args.service,
            cores=args.cores, memory=args.memory, store=args.store,
        )
    except ValueError as e:
        print(f"submit.py: error: {e}", file=sys.stderr)
        return 2
    os.makedirs(chunk_dir(output), exist_ok=True)
    if args.print_spec:
        print(serialize(ol))
        return 0
    launch = {"pause": args.pause}
    if args.cuebot:
        launch["server"] = args.cuebot
    jobs = outline.cuerun.launch(ol, use_pycuerun=False, **launch)
    for job in jobs or []:
        print(f"submitted {job.name()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
