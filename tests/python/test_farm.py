"""The farm integrations of README.md, "Farm", run for real where they can be:

* Open Job Description: farm/openjd/curvenet-bake.template.yaml run locally
  with the `openjd` runner (chunked bake step, then the stitch step) on the
  hand_wave shot; the stitched layer is byte for byte a whole-range bake.
* OpenCue: farm/opencue/submit.py builds the outline with PyOutline; its
  serialised job spec is checked against the content models of OpenCue's
  job spec DTD (cjsl-1.15, transcribed below: the DTD is served by Cuebot
  and does not ship with pyoutline), then run as Cuebot would dispatch it
  (range split into chunks, #FRAME_START#/#FRAME_END# replaced, each command
  through a shell, the stitch after the bake layer) and compared with a
  whole-range bake.

Needs the debug binary (`cargo test --workspace` builds it; scripts/test
runs the Rust tests first). CURVENET_BIN overrides its path."""

import contextlib
import io
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "farm" / "openjd" / "curvenet-bake.template.yaml"
SHOT = ROOT / "fixtures" / "shots" / "hand_wave" / "shot.usda"

sys.path.insert(0, str(ROOT / "farm" / "opencue"))
import submit  # noqa: E402


def _binary():
    if os.environ.get("CURVENET_BIN"):
        return pathlib.Path(os.environ["CURVENET_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "debug" / "curvenet"


@pytest.fixture(scope="module")
def curvenet():
    binary = _binary()
    assert binary.exists(), f"{binary} is missing: build it first (cargo build --ignore-rust-version) or set CURVENET_BIN"
    return binary.resolve()


def _openjd():
    beside = pathlib.Path(sys.executable).parent / "openjd"
    found = str(beside) if beside.exists() else shutil.which("openjd")
    assert found, "the openjd runner is missing: scripts/python-env installs farm/requirements.txt"
    return found


def _whole_bake(curvenet, out, frames):
    """The reference: one `curvenet bake` of the whole range."""
    run = subprocess.run(
        [str(curvenet), "bake", str(SHOT), "--out", str(out), "--frames", frames, "--quiet"],
        capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 0, run.stderr
    return out.read_bytes()


def _openjd_run(curvenet, output, first, last, chunk, shot=SHOT, store=None):
    return subprocess.run(
        [
            _openjd(), "run", str(TEMPLATE), "--step", "Stitch", "--run-dependencies",
            "-p", f"Shot={shot}", "-p", f"Output={output}",
            "-p", f"FrameStart={first}", "-p", f"FrameEnd={last}",
            "-p", f"ChunkSize={chunk}", "-p", f"Curvenet={curvenet}",
            *(["-p", f"Store={store}"] if store else []),
        ],
        capture_output=True, text=True, timeout=600,
    )


def test_openjd_run_with_a_store_binds_once_and_stitches_the_whole_range_bake(curvenet, tmp_path):
    output = tmp_path / "hand_wave.usdc"
    store = tmp_path / "store"
    run = _openjd_run(curvenet, output, 1, 24, 8, store=store)
    assert run.returncode == 0, run.stdout + run.stderr
    assert output.read_bytes() == _whole_bake(curvenet, tmp_path / "whole.usdc", "1-24")
    # One binding (the shot's one mesh), written by the Bind step; its scratch file is gone.
    assert [p.suffix for p in store.iterdir() if not p.name.startswith(".")] == [".cnb"]
    assert sorted(p.name for p in output.with_name("hand_wave.usdc.chunks").iterdir()) == ["1-8.usdc", "17-24.usdc", "9-16.usdc"]
    # The chunks read it: their summaries say so (the runner logs each task's stderr).
    assert (run.stdout + run.stderr).count("(loaded from the store)") == 3, run.stdout[-3000:]


# -- Open Job Description -----------------------------------------------------


def test_openjd_template_passes_the_runners_checks():
    run = subprocess.run([_openjd(), "check", str(TEMPLATE)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "passes validation" in run.stdout


@pytest.mark.parametrize("ext", ["usdc", "usda"])
def test_openjd_run_stitches_the_chunks_into_the_whole_range_bake(curvenet, tmp_path, ext):
    output = tmp_path / "shots" / f"hand_wave.{ext}"  # its directory is made by the bake tasks
    run = _openjd_run(curvenet, output, 1, 24, 8)
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    assert "Chunks run: 5" in log, log  # the bind step (nothing to do without a store), three bake chunks and the stitch
    chunks = sorted(p.name for p in (tmp_path / "shots" / f"hand_wave.{ext}.chunks").iterdir())
    assert chunks == ["1-8.usdc", "17-24.usdc", "9-16.usdc"], chunks
    whole = _whole_bake(curvenet, tmp_path / f"whole.{ext}", "1-24")
    assert output.read_bytes() == whole, "the stitched OpenJD job differs from a whole-range bake"

    # Resubmitted over a shorter range with the old chunks still there: the
    # stitch keeps its own frames (--frames) and the stale ones do no harm.
    run = _openjd_run(curvenet, output, 1, 12, 8)
    assert run.returncode == 0, run.stdout + run.stderr
    assert output.read_bytes() == _whole_bake(curvenet, tmp_path / f"part.{ext}", "1-12")


def test_openjd_run_fails_on_a_bad_shot_with_the_bakes_exit_status(curvenet, tmp_path):
    output = tmp_path / "out.usdc"
    run = _openjd_run(curvenet, output, 1, 4, 2, shot=tmp_path / "missing.usda")
    log = run.stdout + run.stderr
    assert run.returncode != 0, log
    assert "missing.usda" in log and "exited with code: 2" in log, log
    assert not output.exists()


# -- OpenCue ------------------------------------------------------------------

# OpenCue's cjsl-1.15 DTD, as content models: each element's children in
# order, with how many times each may occur ("?" 0-1, "" 1, "*" 0+, "+" 1+).
DTD_CHILDREN = {
    "spec": "facility? dept? show shot user email? uid? job* depends*",
    "job": "paused? priority? maxretries? maxcores? maxgpus? autoeat? localbook? os? env* layers?",
    "layers": "layer+",
    "layer": "cmd range chunk cores? threadable? memory? gpus? gpu? gpu_memory? timeout? timeout_llu? tags? limits? env* services? outputs*",
    "limits": "limit+",
    "services": "service+",
    "outputs": "output*",
    "env": "key*",
    "depends": "depend*",
    "depend": "depjob deplayer? depframe? onjob onlayer? onframe?",
}
DTD_REQUIRED_ATTRIBUTES = {"job": {"name"}, "layer": {"name", "type"}, "output": {"name"}, "key": {"name"}, "depend": {"type"}}
DTD_ENUMS = {
    ("layer", "type"): {"Render", "Util", "Post"},
    ("depend", "type"): {
        "LAYER_ON_SIM_FRAME", "PREVIOUS_FRAME", "JOB_ON_JOB", "JOB_ON_LAYER", "JOB_ON_FRAME", "LAYER_ON_JOB",
        "LAYER_ON_FRAME", "LAYER_ON_LAYER", "FRAME_ON_JOB", "FRAME_ON_LAYER", "FRAME_ON_FRAME", "FRAME_BY_FRAME",
    },
}
NMTOKEN = re.compile(r"[A-Za-z0-9._:-]+")


def _check_against_dtd(element, where="spec"):
    """Raises AssertionError naming the element where the spec breaks the DTD."""
    model = DTD_CHILDREN.get(element.tag)
    children = [c.tag for c in element]
    if model is None:
        assert not children, f"{where}: <{element.tag}> holds text only, not {children}"
    else:
        i = 0
        for item in model.split():
            name, mark = item.rstrip("?*+"), item[len(item.rstrip("?*+")):]
            n = 0
            while i < len(children) and children[i] == name and (mark in "*+" or n == 0):
                i, n = i + 1, n + 1
            assert n >= (1 if mark in ("", "+") else 0), f"{where}: <{element.tag}> lacks <{name}> (children {children})"
        assert i == len(children), f"{where}: <{element.tag}> may not hold <{children[i]}> there (model {model}; children {children})"
    for attr in DTD_REQUIRED_ATTRIBUTES.get(element.tag, ()):
        assert attr in element.attrib, f"{where}: <{element.tag}> lacks attribute {attr}"
    for (tag, attr), allowed in DTD_ENUMS.items():
        if element.tag == tag and attr in element.attrib:
            assert element.attrib[attr] in allowed, f"{where}: <{tag} {attr}={element.attrib[attr]!r}> is not one of {allowed}"
    if element.tag in ("job", "layer", "output", "key"):
        assert NMTOKEN.fullmatch(element.attrib["name"]), f"{where}: name {element.attrib['name']!r} is not an NMTOKEN"
    for c in element:
        _check_against_dtd(c, f"{where}/{c.tag}")


def _spec(tmp_path, monkeypatch, first, last, chunk, curvenet="curvenet"):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))  # PyOutline writes its session under ~/.opencue
    ol = submit.build_outline(
        str(SHOT), str(tmp_path / "out" / "hand_wave.usdc"), first, last, chunk,
        curvenet=str(curvenet), show="testing", shot_name="hand_wave", user="td",
    )
    return submit.serialize(ol)


def test_opencue_job_spec_follows_the_dtd_with_a_chunked_bake_and_a_dependent_stitch(tmp_path, monkeypatch):
    text = _spec(tmp_path, monkeypatch, 1, 24, 10)
    assert re.search(r'<!DOCTYPE spec PUBLIC "SPI Cue\s+Specification Language" "[^"]*/cjsl-1\.\d+\.dtd">', text), text[:300]
    spec = ET.fromstring(text)
    _check_against_dtd(spec)

    job = spec.find("job")
    layers = {layer.get("name"): layer for layer in job.find("layers")}
    assert list(layers) == ["bake", "stitch"]
    bake, stitch = layers["bake"], layers["stitch"]
    assert (bake.findtext("range"), bake.findtext("chunk")) == ("1-24", "10")
    assert (stitch.findtext("range"), stitch.findtext("chunk")) == ("1", "1")
    # No pycuerun wrapper: the commands are curvenet itself.
    bake_argv = shlex.split(bake.findtext("cmd"))
    assert bake_argv[:3] == ["curvenet", "bake", str(SHOT)], bake_argv
    assert bake_argv[3:] == ["--out", f"{tmp_path}/out/hand_wave.usdc.chunks/#FRAME_START#-#FRAME_END#.usdc", "--frames", "#FRAME_START#-#FRAME_END#"]
    stitch_argv = shlex.split(stitch.findtext("cmd"))
    chunks = [f"{tmp_path}/out/hand_wave.usdc.chunks/{r}.usdc" for r in ("1-10", "11-20", "21-24")]
    assert stitch_argv == ["curvenet", "stitch", *chunks, "--frames", "1-24", "--out", f"{tmp_path}/out/hand_wave.usdc"]
    assert "pycuerun" not in text

    depends = spec.find("depends").findall("depend")
    assert len(depends) == 1
    d = depends[0]
    assert d.get("type") == "LAYER_ON_LAYER" and d.get("anyframe") == "False"
    name = job.get("name")
    assert [d.findtext(k) for k in ("depjob", "deplayer", "onjob", "onlayer")] == [name, "stitch", name, "bake"]


def test_the_dtd_check_catches_what_cuebot_would_refuse(tmp_path, monkeypatch):
    spec = ET.fromstring(_spec(tmp_path, monkeypatch, 1, 8, 4))
    bake = spec.find("job/layers/layer")
    chunk = bake.find("chunk")
    bake.remove(chunk)
    with pytest.raises(AssertionError, match="lacks <chunk>"):
        _check_against_dtd(spec)
    bake.insert(0, chunk)
    with pytest.raises(AssertionError, match="lacks <cmd>|may not hold"):
        _check_against_dtd(spec)
    bake.remove(chunk)
    bake.insert(2, chunk)
    spec.find("depends/depend").set("type", "LAYER_AFTER_LAYER")
    with pytest.raises(AssertionError, match="LAYER_AFTER_LAYER"):
        _check_against_dtd(spec)


def _dispatch(layer):
    """Cuebot: the layer's frames in chunks, tokens replaced; RQD: the command
    through a shell. Returns each task's stderr."""
    a, _, b = layer.findtext("range").partition("-")
    frames = list(range(int(a), int(b or a) + 1))
    size = int(layer.findtext("chunk"))
    errs = []
    for k in range(0, len(frames), size):
        part = frames[k:k + size]
        cmd = layer.findtext("cmd").replace("#FRAME_START#", str(part[0])).replace("#FRAME_END#", str(part[-1]))
        run = subprocess.run(["/bin/sh", "-c", cmd], capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, f"{layer.get('name')} frames {part[0]}-{part[-1]}: {run.stderr}"
        errs.append(run.stderr)
    return errs


def test_opencue_job_runs_as_cuebot_dispatches_it_into_the_whole_range_bake(curvenet, tmp_path, monkeypatch):
    first, last, chunk = 1, 24, 10
    # submit.py's command line, as a TD runs it (it also makes the chunk directory).
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    output = tmp_path / "out" / "hand_wave.usdc"
    output.parent.mkdir()
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = submit.main([str(SHOT), "-o", str(output), "--frames", f"{first}-{last}", "--chunk-size", str(chunk),
                            "--curvenet", str(curvenet), "--print-spec"])
    assert code == 0
    assert (tmp_path / "out" / "hand_wave.usdc.chunks").is_dir()
    spec = ET.fromstring(buf.getvalue())
    layers = {layer.get("name"): layer for layer in spec.find("job/layers")}

    _dispatch(layers["bake"])
    assert sorted(p.name for p in output.with_name("hand_wave.usdc.chunks").iterdir()) == ["1-10.usdc", "11-20.usdc", "21-24.usdc"]
    _dispatch(layers["stitch"])
    assert output.read_bytes() == _whole_bake(curvenet, tmp_path / "whole.usdc", f"{first}-{last}")


def test_opencue_job_with_a_store_binds_in_its_own_layer_and_bakes_the_whole_range(curvenet, tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    output = tmp_path / "out" / "hand_wave.usdc"
    output.parent.mkdir()
    store = tmp_path / "store"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = submit.main([str(SHOT), "-o", str(output), "--frames", "1-24", "--chunk-size", "10",
                            "--curvenet", str(curvenet), "--store", str(store), "--print-spec"])
    assert code == 0
    spec = ET.fromstring(buf.getvalue())
    _check_against_dtd(spec)
    layers = {layer.get("name"): layer for layer in spec.find("job/layers")}
    assert list(layers) == ["bind", "bake", "stitch"]
    pairs = [(d.findtext("deplayer"), d.findtext("onlayer")) for d in spec.find("depends").findall("depend")]
    assert sorted(pairs) == [("bake", "bind"), ("stitch", "bake")]
    assert shlex.split(layers["bake"].findtext("cmd"))[-2:] == ["--store", str(store)]
    logs = {name: _dispatch(layers[name]) for name in ("bind", "bake", "stitch")}
    assert output.read_bytes() == _whole_bake(curvenet, tmp_path / "whole.usdc", "1-24")
    assert [p.suffix for p in store.iterdir() if not p.name.startswith(".")] == [".cnb"]
    assert not (output.with_name("hand_wave.usdc.chunks") / ".bind.usdc").exists()
    bakes = logs["bake"]
    assert len(bakes) == 3 and all("(loaded from the store)" in err for err in bakes), bakes


def test_submit_refuses_bad_frames_and_outputs(capsys):
    assert submit.parse_frames("-5--1") == (-5, -1)
    assert submit.parse_frames("7") == (7, 7)
    assert submit.chunk_ranges(1, 24, 10) == [(1, 10), (11, 20), (21, 24)]
    assert submit.chunk_ranges(5, 5, 3) == [(5, 5)]
    assert submit.main([str(SHOT), "-o", "x.usdc", "--frames", "9-1", "--print-spec"]) == 2
    assert "9-1" in capsys.readouterr().err
    assert submit.main([str(SHOT), "-o", "x.obj", "--frames", "1-9", "--print-spec"]) == 2
    assert ".usda or .usdc" in capsys.readouterr().err
