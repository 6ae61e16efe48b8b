"""A stage stopped by SIGTERM (scancel, a time limit) leaves nothing half-written behind."""

import os
import signal
import subprocess
import sys
import time


def test_sigterm_mid_render_leaves_no_temporary_output(tmp_path):
    out = tmp_path / "capture"
    env = dict(os.environ)
    proc = subprocess.Popen([sys.executable, "-m", "invrender.cli", "synthesize", "room", "--out", str(out),
                             "--spp", "100000"], env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not any(".tmp-" in p.name for p in tmp_path.iterdir()):
            time.sleep(0.2)
        time.sleep(1.0)  # inside the render loop by now
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:  # never leave a 100,000-spp render running
            proc.kill()
            proc.wait()
    assert proc.returncode != 0
    assert list(tmp_path.iterdir()) == [], [p.name for p in tmp_path.iterdir()]
