# Ctrl-C during a long call: the call stops at its next unit of work, KeyboardInterrupt reaches the caller,
# and what the library holds is still a certified map.
import _thread
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import lidef
from conftest import SMALL, SOURCE_DIR

TWIST = SOURCE_DIR / "data" / "scenarios" / "beam_twist360.json"
# Many Newton iterations through the continuation's stages: longer than the interrupt's delay.
LONG_SOLVE = dict(SMALL, max_iterations=400)


def interrupt_after(seconds):
    """Ctrl-C as the interpreter sees it (SIGINT's flag, set from another thread) after `seconds`."""
    t = threading.Timer(seconds, _thread.interrupt_main)
    t.start()
    return t


def test_ctrl_c_stops_a_session_solve_and_keeps_the_last_certified_map(beam):
    twist = lidef.read_scenario(str(TWIST))
    s = lidef.Session(beam, **LONG_SOLVE)
    s.set_handles(twist.sources)
    timer = interrupt_after(0.5)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        s.solve(twist.targets)
    stopped = time.monotonic() - start
    timer.join()
    assert stopped < 5.0, stopped  # within an iteration or two of the interrupt
    # The session holds the last certified map: certified, and a later solve goes on from it.
    assert lidef.certify(beam, s.coefficients, samples=SMALL["samples"]).certified
    r = s.solve(twist.sources)  # back to the rest pose
    assert r.certified


def test_ctrl_c_stops_the_precomputation(beam, tmp_path, monkeypatch):
    # An empty cache of its own: the whole precomputation runs (the subspace, the voxel sampling, which is not
    # interruptible, then the basis derivatives at the samples in interruptible chunks), and a completed one
    # would store its entry there. Interrupted, it stores none: that, not the time, shows it was cut short.
    monkeypatch.setenv("LIDEF_CACHE_DIR", str(tmp_path))
    timer = interrupt_after(0.3)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        lidef.Session(beam, samples=30000)
    timer.join()
    assert not list(tmp_path.glob("solver-*")), "the precomputation ran to its end"
    assert time.monotonic() - start < 30.0


def test_a_real_sigint_interrupts_deform_in_a_script(tmp_path):
    script = tmp_path / "long.py"
    script.write_text(textwrap.dedent(f"""
        import sys, time
        import lidef
        model = lidef.load_model({str(SOURCE_DIR / 'data' / 'models' / 'beam')!r})
        twist = lidef.read_scenario({str(TWIST)!r})
        print("ready", flush=True)
        start = time.monotonic()
        try:
            lidef.deform(model, twist.sources, twist.targets, **{LONG_SOLVE!r})
            print("finished", flush=True)
        except KeyboardInterrupt:
            print("interrupted after %.2f s" % (time.monotonic() - start), flush=True)
    """))
    child = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, env=dict(os.environ))
    assert child.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=30)
    assert child.returncode == 0, err
    assert out.startswith("interrupted after"), out + err
