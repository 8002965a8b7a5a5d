"""Atomic outputs: a process killed while writing leaves no truncated output file.

A child process runs the real ``asrbf reconstruct`` with the PLY writer slowed down:
it writes half of the file under its temporary name, says so on stdout and waits.
The test then kills it (SIGKILL: nothing can clean up; SIGTERM: the command's
handler unwinds) and checks what is left in the output folder.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import asrbf_mesh as am

CHILD = r"""
import sys, time
import asrbf_mesh._writers as io
from asrbf_mesh.cli import main

real = io.WRITERS[".ply"]

def slow(path, *args, **kwargs):
    real(path, *args, **kwargs)
    with open(path, "r+b") as fh:  # as if the write were half done
        fh.truncate(fh.seek(0, 2) // 2)
    print("writing", path, flush=True)
    time.sleep(120)

io.WRITERS[".ply"] = slow
sys.exit(main(sys.argv[1:]))
"""


@pytest.fixture(scope="module")
def net_file(tmp_path_factory, franke_net: am.Network) -> Path:
    return franke_net.save(tmp_path_factory.mktemp("net") / "franke.asrbf")


def kill_while_writing(net_file: Path, out: Path, sig: int) -> tuple[int, str, str]:
    """Run the slowed ``reconstruct`` into ``out``; send ``sig`` once it is mid-write."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, "reconstruct", str(net_file), "-o", str(out),
         "--resolution", "41"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("writing "), (line, proc.stderr.read())
        tmp = Path(line.split(" ", 1)[1].strip())
        assert tmp.parent == out.parent and tmp.name.startswith(f".{out.name}.")
        assert tmp.exists()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    return proc.returncode, tmp.name, err


@pytest.mark.parametrize("existing", [False, True], ids=["new", "overwrite"])
def test_sigkill_mid_write_leaves_no_truncated_output(net_file: Path, tmp_path: Path,
                                                      existing: bool) -> None:
    out = tmp_path / "surface.ply"
    if existing:
        out.write_bytes(b"the previous, complete output")
    code, tmp_name, _ = kill_while_writing(net_file, out, signal.SIGKILL)
    assert code == -signal.SIGKILL
    if existing:
        assert out.read_bytes() == b"the previous, complete output"
    else:
        assert not out.exists()
    # nothing can delete the temporary file of a killed process; it is hidden and
    # never takes the output's name
    assert sorted(os.listdir(tmp_path)) == sorted([tmp_name] + (["surface.ply"] * existing))


@pytest.mark.parametrize("existing", [False, True], ids=["new", "overwrite"])
def test_sigterm_mid_write_cleans_up(net_file: Path, tmp_path: Path, existing: bool) -> None:
    out = tmp_path / "surface.ply"
    if existing:
        out.write_bytes(b"the previous, complete output")
    code, _, err = kill_while_writing(net_file, out, signal.SIGTERM)
    assert code == 128 + signal.SIGTERM
    assert err.strip().splitlines()[-1] == "asrbf: terminated"
    assert sorted(os.listdir(tmp_path)) == (["surface.ply"] if existing else [])
    if existing:
        assert out.read_bytes() == b"the previous, complete output"


def test_an_unkilled_run_writes_the_complete_file(net_file: Path, tmp_path: Path,
                                                  franke_net: am.Network) -> None:
    out = tmp_path / "surface.ply"
    done = subprocess.run([sys.executable, "-m", "asrbf_mesh.cli", "reconstruct",
                           str(net_file), "-o", str(out), "--resolution", "41"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    want = am.reconstruct(franke_net, resolution=41)
    back = am.load_scan(out)
    assert (back.n_points, back.n_faces) == (want.n_vertices, want.n_faces)
    assert os.listdir(tmp_path) == ["surface.ply"]
