"""`gdlearn render` end to end, in subprocesses: the three output formats, --buffers, a scene error
(file:line + fix, exit status 2) and Ctrl-C (SIGINT) saving what was accumulated."""
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from gdlearn.io import read_image

#: Bound on one child process (it may JIT-compile numba kernels cold, which took > 120 s on a busy
#: 2-core machine). It only bounds a hang: subprocess.run kills the child when it expires, and no
#: assertion depends on how long the child took.
SUBPROCESS_TIMEOUT = 1800


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "cornell-box.xml")


def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "gdlearn", "render", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=SUBPROCESS_TIMEOUT, **kw)


def test_render_writes_every_format_and_buffers(tmp_path):
    r = _cli(SCENE, "--spp", "4", "--set", "res=16", "--out", str(tmp_path / "a.npy"),
             "--buffers", str(tmp_path / "buf"), "--seed", "3")
    assert r.returncode == 0, r.stderr
    a = read_image(tmp_path / "a.npy")
    assert a.shape == (16, 16, 3) and np.isfinite(a).all() and a.mean() > 0
    assert {"primal.npy", "primal_a.npy", "primal_b.npy", "primal_var.npy"} <= set(os.listdir(tmp_path / "buf"))
    assert np.array_equal(np.load(tmp_path / "buf" / "primal.npy"), a)
    for ext in ("exr", "png"):
        r = _cli(SCENE, "--spp", "2", "--set", "res=8", "--out", str(tmp_path / f"a.{ext}"), "--no-progress")
        assert r.returncode == 0, r.stderr
        assert read_image(tmp_path / f"a.{ext}").shape == (8, 8, 3)


def test_scene_error_prints_file_line_and_fix(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0">\n  <shape type="sphere">\n    <float name="radius" value="-1"/>\n'
                   '  </shape>\n</scene>\n')
    r = _cli(str(bad), "--spp", "1", "--out", str(tmp_path / "x.npy"))
    assert r.returncode == 2
    assert "bad.xml:" in r.stderr and "fix" in r.stderr and "Traceback" not in r.stderr


def test_effects_and_threads_options(tmp_path):
    r = _cli(SCENE, "--spp", "2", "--set", "res=8", "--effects", "direct", "--threads", "1",
             "--out", str(tmp_path / "d.npy"), "--no-progress")
    assert r.returncode == 0, r.stderr
    r = _cli(SCENE, "--spp", "2", "--set", "res=8", "--effects", "nonsense", "--out", str(tmp_path / "e.npy"))
    assert r.returncode == 2 and "nonsense" in r.stderr


def test_shift_option_is_checked_before_rendering(tmp_path):
    # --shift belongs to gpt; a wrong integrator or an unknown policy stops with exit 2 and says why.
    r = _cli(SCENE, "--spp", "1", "--set", "res=8", "--shift", "replay", "--out", str(tmp_path / "s.npy"))
    assert r.returncode == 2 and "--integrator gpt" in r.stderr
    r = _cli(SCENE, "--integrator", "gpt", "--spp", "1", "--set", "res=8", "--shift", "teleport",
             "--out", str(tmp_path / "t.npy"))
    assert r.returncode == 2 and "teleport" in r.stderr and "halfvector+reconnection" in r.stderr
    assert not (tmp_path / "s.npy").exists() and not (tmp_path / "t.npy").exists()


def _stderr_lines(p):
    """A queue that receives the child's stderr lines (None at EOF), read by a daemon thread so that
    waiting for a line never blocks the test beyond its own bound."""
    q = queue.Queue()

    def pump():
        for line in p.stderr:
            q.put(line)
        q.put(None)

    threading.Thread(target=pump, daemon=True).start()
    return q


#: Upper bound on waiting for the child's "rendering" line (JIT compilation of the path tracer; cold
#: on a busy 2-core machine it took > 120 s). It only bounds a hang: the test never acts on a timeout
#: except by failing, and the child is killed whatever happens.
JIT_WAIT = 1800


def _interrupt_after(seconds, out):
    """Start a 10^6 spp render, send SIGINT ``seconds`` after it says it is rendering, and return
    its exit status and the stderr lines after that point."""
    # The child gets SIGINT's default disposition, as a command started at a terminal has: started
    # from a background job (`make test &`, a CI runner) the suite inherits SIGINT ignored, an
    # ignored signal stays ignored across exec, Python then installs no KeyboardInterrupt handler,
    # and the 10^6 spp render would run until JIT_WAIT ran out.
    p = subprocess.Popen([sys.executable, "-m", "gdlearn", "render", SCENE, "--spp", "1000000", "--set", "res=16",
                          "--out", str(out), "--no-progress"], cwd=ROOT, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        lines = _stderr_lines(p)
        seen = []
        while not any("rendering" in ln for ln in seen):     # printed after warmup(): the JIT is done
            try:
                line = lines.get(timeout=JIT_WAIT)
            except queue.Empty:
                pytest.fail(f"no 'rendering' line after {JIT_WAIT} s; stderr so far: {''.join(seen)}")
            if line is None:
                pytest.fail(f"gdlearn render exited ({p.wait()}) before rendering: {''.join(seen)}")
            seen.append(line)
        time.sleep(seconds)
        p.send_signal(signal.SIGINT)
        code = p.wait(timeout=JIT_WAIT)
        rest = []
        while (line := lines.get(timeout=JIT_WAIT)) is not None:
            rest.append(line)
        return code, "".join(rest)
    finally:
        if p.poll() is None:        # whatever happened above: never leave a 10^6 spp render running
            p.kill()
            p.wait()


@pytest.mark.skipif(os.name != "posix", reason="SIGINT delivery to a child process")
def test_ctrl_c_saves_what_was_accumulated(tmp_path):
    out = tmp_path / "int.npy"
    # A 16x16 pass takes about a millisecond once compiled, but on a loaded 2-core CI machine the
    # first one once took longer than a second. An interrupt before the first pass is a correct
    # outcome of its own (exit 130, nothing written: tests/test_interrupt.py); then the test waits
    # longer, so that it always ends up checking a save.
    for seconds in (1.0, 5.0, 25.0, 125.0):
        code, rest = _interrupt_after(seconds, out)
        assert code == 130, rest
        if "interrupted before the first pass; nothing written" not in rest:
            break
        assert not out.exists(), rest
    assert "interrupted; saved what was accumulated" in rest, rest
    spp = int(re.search(r": (\d+) spp in", rest).group(1))
    assert spp >= 1, rest
    img = read_image(out)
    assert img.shape == (16, 16, 3) and np.isfinite(img).all() and img.mean() > 0
