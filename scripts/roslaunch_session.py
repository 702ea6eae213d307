"""A roslaunch started for a measurement (bench_bed.py, soak.py) and always torn down after it."""
import contextlib
import os
import signal
import subprocess


@contextlib.contextmanager
def launched(command):
    """Runs `command` (a roslaunch argv) quietly in its own process group; on leaving the block the
    group gets SIGINT, and SIGKILL if it has not ended 30 s later. Yields the Popen."""
    launch = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=os.setsid)
    try:
        yield launch
    finally:
        os.killpg(os.getpgid(launch.pid), signal.SIGINT)
        try:
            launch.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(os.getpgid(launch.pid), signal.SIGKILL)
