"""The browser viewer (`/viewer`), end to end in Debian's Chromium.

`curvenet serve --open-stage` opens the hand_wave shot; a headless Chromium
(no sandbox, no GPU: WebGL2 through SwiftShader, background networking off)
driven over the DevTools protocol on a pipe (`--remote-debugging-pipe`, no
port, no websocket) loads the page and waits for the first frame. Then:

- the screenshot is not blank: the shaded hand and the curvenet's colour are in it;
- the counts in the side panel are those of `curvenet inspect --bind --json`
  (a separate code path: the command line's own binding) and of the API;
- moving the frame slider changes the rendered image, and moving it back
  restores it; playback advances the frames and pauses;
- clicking the hand picks a face, and the panel lists that face's cut-faces;
- the page loaded nothing from anywhere but the server.

And on stages made here (a second server): a curvenet drawn far from the
surface and a mesh with coincident vertices are refused, yet the page
draws the mesh and the curvenet with the element the error names in the
highlight colour and framed; on a plate with a trench, a line bridging the
trench (`segment_detour`) and two lines whose projections cross
(`curves_touch`) bind, and their segments are highlighted; clicking the
warning frames its segment.

Chromium comes from scripts/chromium (installs the `chromium` package where
missing; CURVENET_CHROMIUM names one). The screenshot goes to
target/viewer/viewer.png; with CURVENET_UPDATE_SCREENSHOT=1 also to
docs/viewer.png (the README's). Needs the debug binary like
test_service_client.py (CURVENET_BIN overrides its path)."""

import base64
import fcntl
import json
import os
import pathlib
import queue
import shutil
import struct
import subprocess
import tempfile
import threading
import time
import urllib.error
import urllib.request
import zlib

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
STAGE = ROOT / "fixtures" / "shots" / "hand_wave" / "shot.usda"
WIDTH, HEIGHT = 1100, 680
PANEL = 310  # the side panel's width (viewer.css); the canvas is the rest
BACKGROUND = np.array([27, 30, 35])  # the canvas clear colour (viewer.js)


def _binary():
    if os.environ.get("CURVENET_BIN"):
        return pathlib.Path(os.environ["CURVENET_BIN"])
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    return target / "debug" / "curvenet"


def _chromium():
    """The Chromium of scripts/chromium, installing it when missing."""
    found = subprocess.run([str(ROOT / "scripts" / "chromium")], capture_output=True, text=True)
    if found.returncode != 0 or not found.stdout.strip():
        pytest.fail(f"no Chromium for the viewer test (scripts/chromium): {found.stderr.strip()}")
    return found.stdout.strip().splitlines()[-1]


# ------------------------------------------------------------------ PNG


def decode_png(data):
    """An 8-bit RGB(A), non-interlaced PNG as an (H, W, 3) uint8 array."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, header = 8, [], None
    while pos < len(data):
        (n, kind) = struct.unpack(">I4s", data[pos:pos + 8])
        chunk = data[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat.append(chunk)
        elif kind == b"IEND":
            break
    width, height, depth, color, _, _, interlace = header
    assert depth == 8 and interlace == 0 and color in (2, 6), f"unsupported PNG: depth {depth}, colour type {color}"
    bpp = 3 if color == 2 else 4
    stride = width * bpp
    raw = zlib.decompress(b"".join(idat))
    rows = []
    prev = [0] * stride
    for y in range(height):
        kind = raw[y * (stride + 1)]
        line = list(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        if kind == 1:  # Sub
            arr = np.array(line, dtype=np.int64).reshape(width, bpp)
            line = (np.cumsum(arr, axis=0) % 256).reshape(-1).tolist()
        elif kind == 2:  # Up
            line = [(a + b) & 255 for a, b in zip(line, prev)]
        elif kind == 3:  # Average
            for x in range(stride):
                left = line[x - bpp] if x >= bpp else 0
                line[x] = (line[x] + ((left + prev[x]) >> 1)) & 255
        elif kind == 4:  # Paeth
            for x in range(stride):
                a = line[x - bpp] if x >= bpp else 0
                b = prev[x]
                c = prev[x - bpp] if x >= bpp else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return np.array(rows, dtype=np.uint8).reshape(height, width, bpp)[:, :, :3]


# ------------------------------------------------------------------ DevTools over a pipe


class DevTools:
    """Chromium with `--remote-debugging-pipe`: commands are JSON messages
    ending in a NUL byte, written to the browser's fd 3; answers and events
    come back on its fd 4."""

    def __init__(self, chromium, profile, log):
        to_browser_r, to_browser_w = os.pipe()
        from_browser_r, from_browser_w = os.pipe()
        # The browser's ends move above 4 first, so dup2 onto 3 and 4 cannot clobber one another.
        child_r = fcntl.fcntl(to_browser_r, fcntl.F_DUPFD_CLOEXEC, 10)
        child_w = fcntl.fcntl(from_browser_w, fcntl.F_DUPFD_CLOEXEC, 10)
        os.close(to_browser_r)
        os.close(from_browser_w)

        def wire_pipes():
            os.dup2(child_r, 3)
            os.dup2(child_w, 4)

        args = [
            chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
            "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--remote-debugging-pipe",
            f"--user-data-dir={profile}", f"--window-size={WIDTH},{HEIGHT}", "--hide-scrollbars",
            "--no-first-run", "--no-default-browser-check", "--disable-extensions", "--disable-sync",
            "--disable-component-update", "--disable-dev-shm-usage", "--mute-audio", "about:blank",
        ]
        self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=log, stderr=log,
                                     preexec_fn=wire_pipes, close_fds=False)
        os.close(child_r)
        os.close(child_w)
        self.out = os.fdopen(to_browser_w, "wb", buffering=0)
        self.answers = {}
        self.events = []
        self.cond = threading.Condition()
        self.next_id = 0
        self.reader = threading.Thread(target=self._read, args=(os.fdopen(from_browser_r, "rb", buffering=0),), daemon=True)
        self.reader.start()

    def _read(self, pipe):
        buf = b""
        while True:
            data = pipe.read(1 << 16)
            if not data:
                with self.cond:
                    self.answers[None] = "closed"
                    self.cond.notify_all()
                return
            buf += data
            while b"\0" in buf:
                raw, buf = buf.split(b"\0", 1)
                msg = json.loads(raw)
                with self.cond:
                    if "id" in msg:
                        self.answers[msg["id"]] = msg
                    else:
                        self.events.append(msg)
                    self.cond.notify_all()

    def call(self, method, params=None, session=None, timeout=60):
        with self.cond:
            self.next_id += 1
            n = self.next_id
        msg = {"id": n, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        self.out.write(json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        with self.cond:
            while n not in self.answers:
                left = deadline - time.monotonic()
                assert None not in self.answers, f"Chromium closed the DevTools pipe during {method}"
                assert left > 0, f"{method} got no answer in {timeout} s"
                self.cond.wait(left)
            answer = self.answers.pop(n)
        assert "error" not in answer, f"{method}: {answer['error']}"
        return answer["result"]

    def close(self):
        try:
            self.call("Browser.close", timeout=10)
        except AssertionError:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class Page:
    def __init__(self, tools):
        self.tools = tools
        target = tools.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = tools.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Network"):
            self.call(f"{domain}.enable")
        self.call("Emulation.setDeviceMetricsOverride", {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False})

    def call(self, method, params=None, timeout=60):
        return self.tools.call(method, params, self.session, timeout)

    def eval(self, expression):
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True})
        assert "exceptionDetails" not in r, f"{expression}: {r['exceptionDetails']}"
        return r["result"].get("value")

    def errors(self):
        """Uncaught exceptions and console errors of the page so far."""
        out = []
        for e in self.tools.events:
            if e.get("sessionId") != self.session:
                continue
            if e["method"] == "Runtime.exceptionThrown":
                out.append(e["params"]["exceptionDetails"].get("exception", {}).get("description") or e["params"]["exceptionDetails"]["text"])
            elif e["method"] == "Runtime.consoleAPICalled" and e["params"]["type"] == "error":
                out.append(" ".join(str(a.get("value", a.get("description"))) for a in e["params"]["args"]))
        return out

    def requested_urls(self):
        return [e["params"]["request"]["url"] for e in self.tools.events
                if e.get("sessionId") == self.session and e["method"] == "Network.requestWillBeSent"]

    def wait_for(self, expression, want, timeout=120):
        deadline = time.monotonic() + timeout
        got = None
        while time.monotonic() < deadline:
            # Until the page has loaded, `document.body` may not exist yet.
            got = self.eval(f"(() => {{ try {{ return {expression}; }} catch (e) {{ return 'not yet: ' + e; }} }})()")
            if got == want:
                return
            if self.eval("document.body ? document.body.dataset.state : null") == "error":
                break
            time.sleep(0.1)
        message = self.eval("document.getElementById('message').textContent")
        raise AssertionError(f"{expression} is {got!r}, not {want!r} (page message: {message!r}; errors: {self.errors()})")

    def screenshot(self):
        """The page as the compositor shows it: (PNG bytes, the canvas region as an (H, W, 3) array)."""
        png = base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"})["data"])
        pixels = decode_png(png)
        assert pixels.shape[:2] == (HEIGHT, WIDTH), pixels.shape
        return png, pixels[:, :WIDTH - PANEL]


# ------------------------------------------------------------------ fixtures


def _serve(*stages):
    """`curvenet serve` opening `stages`; yields its URL."""
    binary = _binary()
    assert binary.exists(), f"{binary} is missing: build it first (cargo build --ignore-rust-version) or set CURVENET_BIN"
    env = {k: v for k, v in os.environ.items() if not k.startswith("CURVENET_")}
    opens = [a for st in stages for a in ("--open-stage", str(st))]
    proc = subprocess.Popen(
        [str(binary), "serve", "--addr", "127.0.0.1:0", "--drain-timeout", "5", *opens],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
    )
    timer = threading.Timer(60, proc.kill)
    timer.start()
    first, second = proc.stdout.readline(), proc.stdout.readline()
    timer.cancel()
    assert first.startswith("listening on http://"), f"unexpected first line {first!r}"
    url = first.split("listening on ")[1].strip()
    assert second.strip() == f"viewer: {url}/viewer", second
    try:
        yield url
    finally:
        proc.kill()
        proc.wait()


@pytest.fixture(scope="module")
def server():
    yield from _serve(STAGE)


@pytest.fixture(scope="module")
def tools():
    chromium = _chromium()
    profile = tempfile.mkdtemp(prefix="curvenet-chromium-")
    log = open(os.path.join(profile, "chromium.log"), "wb")
    tools = DevTools(chromium, profile, log)
    try:
        yield tools
    finally:
        tools.close()
        log.close()
        shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="module")
def page(server, tools):
    p = Page(tools)
    p.call("Page.navigate", {"url": f"{server}/viewer"})
    yield p


def _get(url):
    with urllib.request.urlopen(url) as r:
        return json.loads(r.read())


def _set_frame(page, k):
    page.eval(f"(() => {{ const s = document.getElementById('frame'); s.value = '{k}';"
              " s.dispatchEvent(new Event('input')); })()")
    page.wait_for("document.body.dataset.rendered", str(k))
    # One more animation frame, so that the drawn frame is the composited one.
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")


def _changed(a, b):
    """Fraction of pixels that differ by more than a little in any channel."""
    return float(np.mean(np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 8))


# ------------------------------------------------------------------ the test


def test_viewer_draws_the_shot_counts_match_and_the_slider_moves_it(server, page):
    page.wait_for("document.body.dataset.state === 'ready' && document.body.dataset.rendered", "0")
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    assert page.eval("document.getElementById('frame').max") == "23"  # hand_wave: frames 1-24

    # Not blank: the shaded hand and the curvenet are drawn over the background.
    _, first = page.screenshot()
    not_background = np.abs(first.astype(int) - BACKGROUND).max(axis=2) > 12
    assert not_background.mean() > 0.08, f"only {not_background.mean():.1%} of the canvas is not background"
    r, g, b = (first[:, :, k].astype(int) for k in range(3))
    clay = (r > 90) & (r - b > 15) & (abs(r - g) < 40) & (b > 40)
    curve = (r > 200) & (g > 150) & (b < 110)
    wire = (b > 150) & (r < 130) & (g > 100)  # the cut-mesh edges' blue
    # The cut-mesh wireframe covers much of the surface, so the clay shows between its edges.
    assert clay.mean() > 0.015, f"the shaded mesh covers only {clay.mean():.1%} of the canvas"
    assert wire.sum() > 2000, f"only {wire.sum()} pixels have the cut-mesh's colour"
    assert curve.sum() > 200, f"only {curve.sum()} pixels have the curvenet's colour"
    assert len(np.unique(first.reshape(-1, 3), axis=0)) > 200, "too few colours: the image looks flat"

    # The counts shown are the binding's: against `inspect --bind` (the command
    # line binds on its own) and the service's answer.
    shown = page.eval("Object.fromEntries([...document.querySelectorAll('[data-stat]')]"
                      ".map(e => [e.dataset.stat, Number(e.dataset.value)]))")
    report = json.loads(subprocess.run([str(_binary()), "inspect", str(STAGE), "--bind", "--json"],
                                       capture_output=True, text=True, check=True).stdout)
    mesh = report["meshes"][0]
    analysis = report["curvenets"][0]["analysis"]
    expected = dict(mesh["binding"]["stats"], mesh_vertices=mesh["vertices"], mesh_faces=mesh["faces"],
                    intersections=len(analysis["intersections"]), anchors=len(analysis["anchors"]), curvenets=1)
    for name, value in expected.items():
        assert shown.get(name) == value, f"the panel shows {name} = {shown.get(name)}, the binding has {value}"
    api = _get(f"{server}/v1/viewer/stages/0")["binding"]
    for name, value in api["stats"].items():
        assert shown[name] == value, name
    assert shown["blend_shapes"] == api["blend_shapes"] == 1
    shown_warnings = page.eval("Number(document.getElementById('warning-count').dataset.value)")
    data = _get(f"{server}/v1/bindings/{api['binding_id']}/viewer-data")
    assert shown_warnings == len(data["warnings"])

    # The slider moves the hand (the finger curls until frame 13 and comes
    # back at frame 24); moving it back restores the image.
    _set_frame(page, 12)
    _, curled = page.screenshot()
    assert _changed(first, curled) > 0.005, f"frame 13 differs from frame 1 in only {_changed(first, curled):.2%} of the pixels"
    _set_frame(page, 0)
    _, again = page.screenshot()
    assert _changed(first, again) < 0.002, f"frame 1 drawn twice differs in {_changed(first, again):.2%} of the pixels"

    # Playback advances the frames by itself; pause stops it.
    page.eval("document.getElementById('play').click()")
    page.wait_for("Number(document.body.dataset.rendered) >= 3", True, timeout=60)
    page.eval("document.getElementById('play').click()")
    time.sleep(0.5)  # a frame already requested may still arrive
    stopped = page.eval("document.body.dataset.rendered")
    time.sleep(0.5)
    assert page.eval("document.body.dataset.rendered") == stopped, "playback did not pause"

    # Picking: a click on an intersection of the curled finger lists the
    # cut-faces of the face under it.
    _set_frame(page, 12)
    _, curled = page.screenshot()
    r, g, b = (curled[:, :, k].astype(int) for k in range(3))
    ys, xs = np.nonzero((r > 220) & (g < 90) & (b < 90))
    assert len(xs) > 20, "no intersection markers drawn"
    # The pixel nearest the markers' median that is well inside the hand
    # (no background within 6 pixels): by the curvenet, off the silhouette.
    hand = np.abs(curled.astype(int) - BACKGROUND).max(axis=2) > 12
    inside = hand.copy()
    for dy in range(-6, 7, 3):
        for dx in range(-6, 7, 3):
            inside &= np.roll(np.roll(hand, dy, axis=0), dx, axis=1)
    surface_y, surface_x = np.nonzero(inside)
    nearest = np.argmin((surface_x - np.median(xs)) ** 2 + (surface_y - np.median(ys)) ** 2)
    x, y = int(surface_x[nearest]), int(surface_y[nearest])
    page.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})
    for kind in ("mousePressed", "mouseReleased"):
        page.call("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left", "clickCount": 1})
    page.wait_for("document.getElementById('pick-label').dataset.face !== undefined", True, timeout=30)
    face = int(page.eval("document.getElementById('pick-label').dataset.face"))
    cut_faces = int(page.eval("document.getElementById('pick-label').dataset.cutFaces"))
    assert 0 <= face < mesh["faces"]
    assert cut_faces == data["cut"]["face_parent"].count(face) >= 1

    # The README's picture: zoomed in on the picked face, frame 13.
    for _ in range(3):
        page.call("Input.dispatchMouseEvent", {"type": "mouseWheel", "x": x, "y": y, "deltaX": 0, "deltaY": -120})
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    png, zoomed = page.screenshot()
    assert _changed(curled, zoomed) > 0.05, "the wheel did not zoom"
    out = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "viewer"
    out.mkdir(parents=True, exist_ok=True)
    (out / "viewer.png").write_bytes(png)
    if os.environ.get("CURVENET_UPDATE_SCREENSHOT") == "1":
        # At 0.8 scale: a smaller file for the repository.
        clip = {"x": 0, "y": 0, "width": WIDTH, "height": HEIGHT, "scale": 0.8}
        small = base64.b64decode(page.call("Page.captureScreenshot", {"format": "png", "clip": clip})["data"])
        (ROOT / "docs").mkdir(exist_ok=True)
        (ROOT / "docs" / "viewer.png").write_bytes(small)

    # Everything came from the server, and the page raised nothing.
    foreign = [u for u in page.requested_urls() if not u.startswith(server) and not u.startswith("data:")]
    assert not foreign, f"the page loaded from elsewhere: {foreign}"
    assert not page.errors(), page.errors()


# ------------------------------------------------------------------ refused bindings and warnings

VIOLET = np.array([158, 92, 255])  # the highlight colour (highlight.js)


def _violet(pixels):
    """Pixels in the highlight colour (drawn opaque, or blended over the surface)."""
    r, g, b = (pixels[:, :, k].astype(int) for k in range(3))
    return (b > 180) & (r > 110) & (g < 130) & (b - g > 80) & (r - g > 30)


def _clay(pixels):
    r, g, b = (pixels[:, :, k].astype(int) for k in range(3))
    return (r > 90) & (r - b > 15) & (abs(r - g) < 40) & (b > 40)


def _curve(pixels):
    r, g, b = (pixels[:, :, k].astype(int) for k in range(3))
    return (r > 200) & (g > 150) & (b < 110)


def _hand_override(path, edit):
    """A layer over the hand_1k4 fixture: `edit(stage)` authors its opinions."""
    from pxr import Usd
    layer_stage = Usd.Stage.CreateNew(str(path))
    layer_stage.GetRootLayer().subLayerPaths.append(str(ROOT / "fixtures" / "hand" / "hand_1k4.usda"))
    edit(layer_stage)
    layer_stage.GetRootLayer().Save()
    return path


def _far_curve(stage):
    """Lowers a handle of spline 3 by half the hand's diagonal: its samples are far from the surface."""
    from pxr import UsdGeom, Vt
    curves = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Hand/Curvenet"))
    pv = curves.GetPrimvar("curvenet:cv")
    cv = np.array(pv.Get(), dtype=np.float64)
    idx = np.array(pv.GetIndices())
    points = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/Hand/Mesh")).GetPointsAttr().Get())
    diag = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    lifted = int(idx[4 * 3 + 1])
    cv[lifted, 2] -= 0.5 * diag
    pv.Set(Vt.Vec3fArray.FromNumpy(cv.astype(np.float32)))
    UsdGeom.BasisCurves(stage.GetPrimAtPath("/Hand/Curvenet")).GetPointsAttr().Set(
        Vt.Vec3fArray.FromNumpy(cv[idx].astype(np.float32)))


def _coincident_vertices(stage):
    """Moves the first corner of face 10 onto its second: zero-length side, a refused mesh."""
    from pxr import UsdGeom, Vt
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Hand/Mesh"))
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
    indices = np.array(mesh.GetFaceVertexIndicesAttr().Get())
    points = np.array(mesh.GetPointsAttr().Get(), dtype=np.float32)
    start = int(counts[:10].sum())
    a, b = int(indices[start]), int(indices[start + 1])
    points[a] = points[b]
    mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(points))


def _trench_plate(path):
    """A plate over [0, 1]² (100 quads a side) with a trench 0.04 wide and
    0.3 deep along x = 0.5, and one curvenet of three lines: one 0.002 above
    the plate across the trench (its samples over the trench project onto
    the two walls: a detour), and two at heights 0.01 and 0.03 whose
    projections cross at (0.25, 0.75) (curves that touch)."""
    from pxr import Sdf, Usd, UsdGeom, Vt
    n = 100
    xs = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="xy")
    Z = np.where(np.abs(X - 0.5) < 0.02, -0.3, 0.0)
    points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    quads = []
    for j in range(n):
        for i in range(n):
            v = j * (n + 1) + i
            quads.append([v, v + 1, v + n + 2, v + n + 1])
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.Xform.Define(stage, "/Plate")
    stage.GetRootLayer().defaultPrim = "Plate"
    mesh = UsdGeom.Mesh.Define(stage, "/Plate/Mesh")
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([4] * len(quads)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(v) for q in quads for v in q]))
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    mesh.GetPrim().CreateRelationship("curvenet:curvenets", custom=False).SetTargets([Sdf.Path("/Plate/Curvenet")])
    lines = [([0.1, 0.3, 0.002], [0.9, 0.3, 0.002]), ([0.1, 0.6, 0.01], [0.4, 0.9, 0.01]),
             ([0.1, 0.9, 0.03], [0.4, 0.6, 0.03])]
    pool = []
    for a, b in lines:
        a, b = np.array(a), np.array(b)
        pool.extend([a, a + (b - a) / 3, a + 2 * (b - a) / 3, b])
    pool = np.array(pool, dtype=np.float32)
    idx = np.arange(len(pool), dtype=np.int32)
    curves = UsdGeom.BasisCurves.Define(stage, "/Plate/Curvenet")
    curves.CreateTypeAttr(UsdGeom.Tokens.cubic)
    curves.CreateBasisAttr(UsdGeom.Tokens.bezier)
    curves.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray([4] * len(lines)))
    pv = UsdGeom.PrimvarsAPI(curves.GetPrim()).CreatePrimvar("curvenet:cv", Sdf.ValueTypeNames.Point3fArray,
                                                             UsdGeom.Tokens.vertex)
    pv.Set(Vt.Vec3fArray.FromNumpy(pool))
    pv.SetIndices(Vt.IntArray.FromNumpy(idx))
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pool[idx]))
    curves.GetPrim().CreateAttribute("curvenet:sampleDensity", Sdf.ValueTypeNames.Float, custom=False,
                                     variability=Sdf.VariabilityUniform).Set(5.0)
    stage.GetRootLayer().Save()
    return path


@pytest.fixture(scope="module")
def problem_server(tmp_path_factory):
    d = tmp_path_factory.mktemp("viewer-problems")
    stages = [_hand_override(d / "far.usda", _far_curve),
              _hand_override(d / "coincident.usda", _coincident_vertices),
              _trench_plate(d / "trench.usda")]
    yield from _serve(*stages)


def _open(page, url, state):
    page.call("Page.navigate", {"url": url})
    page.wait_for(f"document.body.dataset.state === '{state}' && document.body.dataset.rendered !== '-1'", True)
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")


def _error_code(url):
    """The error code `url` answers (it must answer an error)."""
    try:
        urllib.request.urlopen(url)
    except urllib.error.HTTPError as e:
        return json.loads(e.read())["code"]
    raise AssertionError(f"{url} answered without an error")


def _dataset(page, selector):
    return page.eval(f"Object.assign({{}}, document.querySelector({json.dumps(selector)}).dataset)")


def test_a_refused_binding_shows_the_mesh_the_curvenet_and_the_element_its_error_names(problem_server, tools):
    page = Page(tools)
    # A curve far from the surface: refused, naming a sample of spline 3.
    _open(page, f"{problem_server}/viewer?stage=0", "refused")
    assert page.eval("document.body.dataset.rendered") == "refusal"
    named = _dataset(page, "#problem-label")
    assert named["code"] == "binding_failed" == _error_code(f"{problem_server}/v1/viewer/stages/0"), named
    assert named["element"] == "sample" and named["curvenet"] == "0", named
    refusal = _get(f"{problem_server}/v1/viewer/stages/0/refusal")
    assert named["spline"] == str(refusal["highlight"]["splines"][0]) and named["sample"] == str(refusal["highlight"]["sample"])
    assert page.eval("document.body.dataset.framed") == "sample"
    overlay = page.eval("document.getElementById('overlay').textContent")
    assert overlay.startswith("/Hand/Mesh\nbinding refused: curvenet 0 sample"), overlay
    assert page.eval("getComputedStyle(document.getElementById('problem')).display") != "none"
    _, shot = page.screenshot()
    assert _clay(shot).mean() > 0.01, f"the mesh covers only {_clay(shot).mean():.1%} of the canvas"
    assert _curve(shot).sum() > 100, f"only {_curve(shot).sum()} pixels have the curvenet's colour"
    assert _violet(shot).sum() > 150, f"only {_violet(shot).sum()} pixels have the highlight colour"
    # The highlight is what makes the violet: hidden, it is gone.
    page.eval("(() => { const b = document.querySelector('[data-layer=problems]'); b.checked = false;"
              " b.dispatchEvent(new Event('change')); })()")
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    _, hidden = page.screenshot()
    assert _violet(hidden).sum() < 0.1 * _violet(shot).sum(), "violet pixels remain without the highlight"

    # Coincident vertices: refused, naming the face and its two vertices,
    # filled in violet on the (fan-triangulated) mesh.
    _open(page, f"{problem_server}/viewer?stage=1", "refused")
    named = _dataset(page, "#problem-label")
    assert named["code"] == _error_code(f"{problem_server}/v1/viewer/stages/1"), named
    assert named["element"] == "faces", named
    assert len(named["vertices"].split(",")) == 2 and named["faces"], named
    assert page.eval("document.body.dataset.framed") == "faces"
    _, shot = page.screenshot()
    assert _clay(shot).mean() > 0.01, f"the mesh covers only {_clay(shot).mean():.1%} of the canvas"
    assert _curve(shot).sum() > 100, f"only {_curve(shot).sum()} pixels have the curvenet's colour"
    assert _violet(shot).sum() > 150, f"only {_violet(shot).sum()} pixels have the highlight colour"
    assert not page.errors(), page.errors()


def test_detour_and_touch_warnings_highlight_their_segments(problem_server, tools):
    page = Page(tools)
    _open(page, f"{problem_server}/viewer?stage=2", "ready")
    items = page.eval("[...document.querySelectorAll('#warning-list li')].map(li => Object.assign({}, li.dataset))")
    codes = [i.get("code") for i in items]
    assert "segment_detour" in codes and "curves_touch" in codes, codes
    detour = next(i for i in items if i["code"] == "segment_detour")
    assert detour["element"] == "segment" and detour["curvenet"] == "0" and detour["spline"] == "0", detour
    touch = next(i for i in items if i["code"] == "curves_touch")
    assert sorted(s.split(":")[1] for s in touch["segments"].split()) == ["1", "2"], touch
    # The service carries the same elements in the binding's warnings.
    binding = _get(f"{problem_server}/v1/viewer/stages/2")["binding"]
    wire = {w["code"]: w for w in binding["warnings"]}
    assert wire["segment_detour"]["segment"]["spline"] == 0
    assert {t["segment"]["spline"] for t in wire["curves_touch"]["touches"]} | \
        {t["other"]["spline"] for t in wire["curves_touch"]["touches"]} == {1, 2}
    _, whole = page.screenshot()
    assert _violet(whole).sum() > 50, f"only {_violet(whole).sum()} pixels have the highlight colour"
    # Clicking the detour warning frames its segment: the view zooms in on it.
    page.eval(f"document.querySelector('#warning-list li[data-index=\"{detour['index']}\"]').click()")
    page.wait_for("document.body.dataset.framed", "segment")
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    _, framed = page.screenshot()
    assert _changed(whole, framed) > 0.05, "clicking the warning did not frame its segment"
    assert _violet(framed).sum() > 50, f"only {_violet(framed).sum()} pixels have the highlight colour"
    # Framed: the camera looks at the detour's position, closer than the whole plate.
    target = page.eval("window.curvenetViewer.camera.target")
    radius = page.eval("window.curvenetViewer.camera.radius")
    at = wire["segment_detour"]["segment"]["position"]
    assert np.linalg.norm(np.array(target) - np.array(at)) < 0.05, (target, at)
    assert radius < 0.5 * 0.5 * np.sqrt(2 + 0.3 ** 2), f"the camera still frames the whole plate (radius {radius})"
    assert not page.errors(), page.errors()


# ------------------------------------------------------------------ Curvenet Adjustments

ADJUSTED = ROOT / "fixtures" / "shots" / "hand_adjusted" / "shot.usda"


@pytest.fixture(scope="module")
def adjusted_server():
    yield from _serve(ADJUSTED)


def _vertex_normal(points, triangles, vertex):
    """The area-weighted normal of `vertex` over the triangles around it."""
    around = triangles[(triangles == vertex).any(axis=1)]
    a, b, c = (points[around[:, k]] for k in range(3))
    n = np.cross(b - a, c - a).sum(axis=0)
    return n / np.linalg.norm(n)


def test_a_knot_picked_by_a_click_and_adjusted_bakes_to_the_points_shown(adjusted_server, tools, tmp_path):
    """On the adjusted shot (four CurvenetAdjustment prims keyed at frames 1, 6
    and 12): the knot frames are drawn; a click on a knot picks it; moving it
    1.5% of the diagonal along the surface normal (expressed in the knot's
    frame) and turning it 20° about its z changes the picture; the exported
    layer, baked by `curvenet bake` and read with usd-core, has the points the
    viewer drew. Tolerance 1e-5 of the diagonal: both sides are f32 roundings
    of one f64 solve of the same adjustments (the viewer rounds its values to
    the layer's types before solving), so only the solve's summation order
    could differ; measured 0."""
    from pxr import Usd

    page = Page(tools)
    stage_info = _get(f"{adjusted_server}/v1/viewer/stages")["stages"][0]
    k = stage_info["times"].index(6.0)
    _open(page, f"{adjusted_server}/viewer", "ready")
    _set_frame(page, k)
    binding = _get(f"{adjusted_server}/v1/viewer/stages/0")["binding"]
    data = _get(f"{adjusted_server}/v1/bindings/{binding['binding_id']}/viewer-data")
    diagonal = data["diagonal"]
    knots = data["curvenets"][0]["knots"]
    frame = page.eval("(() => { const f = window.curvenetViewer.view.frames.get(window.curvenetViewer.view.frame);"
                      " return { orientations: f.knot_orientations, adjustments: f.adjustments }; })()")
    assert set(frame["orientations"][0]) == {str(p) for p in knots}, "every knot has its frame"
    assert len(frame["adjustments"]) == 4, "the stage's four adjustments apply"
    _, before = page.screenshot()
    # The knot axes are drawn: pure red, green and blue strokes.
    r, g, b = (before[:, :, c].astype(int) for c in range(3))
    assert ((g > 180) & (r < 120) & (b < 140)).sum() > 30, "no green knot axes"

    # A real click on a knot that stands apart on screen (no other knot within
    # twice the pick radius) and is not the stage's: it is picked.
    screen = page.eval("(() => { const v = window.curvenetViewer;"
                       f" return {json.dumps(knots)}.map(p => v.knotScreenPosition(0, p)); }})()")
    stage_knots = {a["knot"] for a in frame["adjustments"]}
    chosen = None
    for p, s in zip(knots, screen):
        if p in stage_knots or s is None or not (40 < s["x"] < WIDTH - PANEL - 40 and 40 < s["y"] < HEIGHT - 40):
            continue
        others = [o for q, o in zip(knots, screen) if q != p and o is not None]
        if all(np.hypot(o["x"] - s["x"], o["y"] - s["y"]) > 24 for o in others):
            chosen = (p, s)
            break
    assert chosen, "no knot stands apart on screen"
    knot, at = chosen
    x, y = round(at["x"]), round(at["y"])
    page.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})
    for kind in ("mousePressed", "mouseReleased"):
        page.call("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left", "clickCount": 1})
    page.wait_for("document.body.dataset.knot", f"0:{knot}", timeout=30)
    assert not page.eval("document.getElementById('adjust-fields').hidden"), "the panel shows the knot's fields"

    # Translate along the surface normal at the knot, in the knot's frame.
    points = np.array(page.eval("window.curvenetViewer.lastFramePoints()")).reshape(-1, 3)
    triangles = np.array(data["mesh"]["triangles"]).reshape(-1, 3)
    sample = np.array(page.eval(f"Array.from(window.curvenetViewer.view.frames.get({k}).curvenets[0].samples)"
                                f".slice({3 * knots.index(knot)}, {3 * knots.index(knot) + 3})"))
    nearest = int(np.argmin(np.linalg.norm(points - sample, axis=1)))
    normal = _vertex_normal(points, triangles, nearest)
    frame_of = np.array(frame["orientations"][0][str(knot)]).reshape(3, 3)  # columns: the knot's axes
    translate = (frame_of.T @ normal * 0.015 * diagonal).tolist()
    adjusted = {"curvenet": 0, "knot": knot, "translate": translate, "rotate": [0.0, 0.0, 20.0],
                "scale": [1.0, 1.0, 1.0], "attach_tangents": True}
    count = int(page.eval("Number(document.body.dataset.adjusted || 0)"))
    page.eval(f"window.curvenetViewer.setAdjustment({json.dumps(adjusted)}).then(() => true)")
    assert int(page.eval("Number(document.body.dataset.adjusted)")) == count + 1
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    _, after = page.screenshot()
    assert _changed(before, after) > 0.001, f"the adjustment changed only {_changed(before, after):.3%} of the pixels"
    shown = np.array(page.eval("window.curvenetViewer.lastFramePoints()")).reshape(-1, 3)
    moved = np.linalg.norm(shown - points, axis=1).max()
    assert moved > 0.003 * diagonal, f"the surface moved only {moved / diagonal:.2%} of the diagonal"
    # The fields show what was set (translate in model units).
    field = float(page.eval("document.getElementById('adjust-rotate-z').value"))
    assert field == 20.0, field
    # The panel's own fields work too (no keyboard): scale x typed into its number field.
    page.eval("(() => { const f = document.getElementById('adjust-scale-x'); f.value = '1.5';"
              " f.dispatchEvent(new Event('input')); })()")
    page.wait_for("Number(document.body.dataset.adjusted)", count + 2, timeout=60)
    spec = page.eval("window.curvenetViewer.adjustments()")
    assert len(spec) == 1 and spec[0]["scale"] == [1.5, 1, 1] and spec[0]["rotate"] == [0, 0, 20], spec
    assert np.allclose(spec[0]["translate"], translate, rtol=1e-6, atol=1e-9 * diagonal), (spec, translate)
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")
    scaled = np.array(page.eval("window.curvenetViewer.lastFramePoints()")).reshape(-1, 3)
    assert np.abs(scaled - shown).max() > 0, "scaling the knot's tangents changed nothing"
    shown = scaled

    # The export, baked and read back with usd-core, is what the viewer drew.
    layer_text = page.eval("window.curvenetViewer.exportLayer()")
    layer = tmp_path / "adjusted.usda"
    layer.write_text(layer_text)
    out = tmp_path / "baked.usda"
    t = stage_info["times"][k]
    subprocess.run([str(_binary()), "bake", str(layer), "-o", str(out), "--frames", f"{int(t)}-{int(t)}"],
                   check=True, capture_output=True)
    baked_stage = Usd.Stage.Open(str(out))  # kept: a prim of a collected stage expires
    baked = np.array(baked_stage.GetPrimAtPath("/Hand/Mesh").GetAttribute("points").Get(t))
    worst = np.abs(baked - shown).max()
    print(f"viewer vs bake of the export: max |Δ| = {worst:.3e} ({worst / diagonal:.2e} of the diagonal)")
    assert worst <= 1e-5 * diagonal, f"the bake of the export is {worst / diagonal:.2e} of the diagonal from the viewer"
    assert np.abs(baked - points).max() > 0.003 * diagonal, "the bake does not carry the adjustment"
    # The layer is an over on the shot: a new prim for the knot, the shot sublayered.
    composed = Usd.Stage.Open(str(layer))
    prim = composed.GetPrimAtPath(f"/Hand/Curvenet/Knot_{knot}")
    assert prim and prim.GetTypeName() == "CurvenetAdjustment"
    assert prim.GetAttribute("curvenet:knot").Get() == knot
    assert not page.errors(), page.errors()


CAGED = ROOT / "fixtures" / "shots" / "hand_caged" / "shot.usda"


@pytest.fixture(scope="module")
def caged_server():
    yield from _serve(CAGED)


def _toggle(page, layer, on):
    page.eval(f"(() => {{ const b = document.querySelector('[data-layer={layer}]'); b.checked = {str(on).lower()};"
              " b.dispatchEvent(new Event('change')); })()")
    page.eval("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))")


def test_the_cage_of_a_caged_stage_is_drawn_as_a_layer(caged_server, tools):
    page = Page(tools)
    _open(page, f"{caged_server}/viewer?stage=0", "ready")
    # The cage layer is offered, and on, for a binding with a cage.
    assert page.eval("document.getElementById('cage-layer').hidden") is False
    assert page.eval("document.querySelector('[data-layer=cage]').checked") is True
    # A posed frame with rest-cage and posed-cage edits (frame 10 of 1..10).
    times = _get(f"{caged_server}/v1/viewer/stages")["stages"][0]["times"]
    k = times.index(10.0)
    frame = _get(f"{caged_server}/v1/viewer/stages/0/frames/{k}")
    binding = _get(f"{caged_server}/v1/viewer/stages/0")["binding"]
    assert len(frame["cage"]) == 3 * binding["cage"]["vertices"]
    _set_frame(page, k)
    _, with_cage = page.screenshot()
    _toggle(page, "cage", False)
    _, without = page.screenshot()
    changed = _changed(with_cage, without)
    assert changed > 0.002, f"the cage layer changes only {changed:.2%} of the pixels"
    # The cage's own colour is what the layer adds.
    r, g, b = (with_cage[:, :, i].astype(int) for i in range(3))
    mint = (abs(r - 140) < 30) & (g > 200) & (abs(b - 191) < 30)
    r, g, b = (without[:, :, i].astype(int) for i in range(3))
    mint_without = (abs(r - 140) < 30) & (g > 200) & (abs(b - 191) < 30)
    assert mint.sum() > 200 and mint_without.sum() < 0.1 * mint.sum(), (mint.sum(), mint_without.sum())
    _toggle(page, "cage", True)
    _, again = page.screenshot()
    assert _changed(with_cage, again) < 0.002, "the cage drawn again differs"
    assert not page.errors(), page.errors()
