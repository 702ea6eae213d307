"""A roslaunch started for a measurement (bench_bed.py, soak.py) and always torn down after it."""
import contextlib
import os
import signal
import subprocess
import sys


@contextlib.contextmanager
def launched(command):
    """Runs `command` (a roslaunch argv) quietly in its own process group; on leaving the block the
    group gets SIGINT, and SIGKILL if it has not ended 30 s later. Yields the Popen. A SIGTERM to
    this process (kill, a batch system) leaves the block through that teardown: in its own group
    the launch would outlive a killed measurement."""
    launch = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=os.setsid)
    previous = signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    try:
        yield launch
    finally:
        signal.signal(signal.SIGTERM, previous)
        os.killpg(os.getpgid(launch.pid), signal.SIGINT)
        try:
            launch.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(os.getpgid(launch.pid), signal.SIGKILL)
