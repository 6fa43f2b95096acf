"""Plan CSV: format, bit-exact round trip, errors; atomic writes."""

import os
import subprocess
import sys

import numpy as np
import pytest

from cnc_interp.outfile import atomic_write
from cnc_interp.export.csv_io import PlanFileError, read_csv, write_csv
from cnc_interp.plan.trajectory import Trajectory


def make(k=1000, axes="XYZAC", dt=0.001, seed=0):
    rng = np.random.default_rng(seed)
    q = np.cumsum(rng.normal(size=(k, len(axes))), axis=0) * np.pi
    if k > 3 and len(axes) > 2:
        q[0, 0] = -0.0
        q[1, 1] = 1e-300  # tiny, subnormal and huge values all round-trip
        q[2, 2] = 5e-324
        q[3, 0] = 1.2345678901234567e17
    s = np.cumsum(np.abs(rng.normal(size=k)))
    return Trajectory(
        axes=axes,
        dt_s=dt,
        t=np.arange(k) * dt,
        s=s,
        feed=np.concatenate([[0.0], np.diff(s) / dt]),
        q=q,
        line=np.zeros(k, dtype=int),
        planner="vpop",
    )


def test_round_trip_bit_exact(tmp_path):
    tr = make()
    path = str(tmp_path / "p.csv")
    assert write_csv(tr, path) == tr.n_samples
    back = read_csv(path)
    assert back.axes == tr.axes and back.planner == "csv" and back.dt_s == tr.dt_s
    for name in ("t", "s", "feed", "q"):
        a, b = getattr(tr, name), getattr(back, name)
        assert a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64)), name


def test_format_header_and_repr(tmp_path):
    tr = make(k=3, axes="XZ", dt=0.25)
    path = str(tmp_path / "p.csv")
    write_csv(tr, path)
    lines = open(path, "rb").read().split(b"\n")
    assert lines[0] == b"t,s,feed,X,Z"
    assert lines[-1] == b"" and len(lines) == 5  # ends with a newline, no comments
    row = lines[2].decode().split(",")
    assert row[0] == repr(0.25) and row[3] == repr(float(tr.q[1, 0]))
    # same trajectory -> identical bytes
    path2 = str(tmp_path / "p2.csv")
    write_csv(tr, path2)
    assert open(path, "rb").read() == open(path2, "rb").read()


@pytest.mark.parametrize(
    "text,line,fragment",
    [
        ("x,y\n1,2\n", 1, "t,s,feed"),
        ("t,s,feed,X,X\n0,0,0,0,0\n", 1, "distinct"),
        ("t,s,feed,X\n0,0,0,0\n0.001,0,0\n", 3, "fields"),
        ("t,s,feed,X\n0,0,0,0\n0.001,0,0,abc\n", 3, "not a number"),
        ("t,s,feed,X\n0,0,0,0\n0.001,0,0,0\n0.005,0,0,0\n", 4, "fixed period"),
        ("t,s,feed,X\n", 1, "no samples"),
    ],
)
def test_read_errors(tmp_path, text, line, fragment):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(PlanFileError) as info:
        read_csv(str(p))
    assert fragment in info.value.message
    assert info.value.location.line == line, info.value.format()
    assert info.value.exit_code == 2


def test_single_row_needs_dt(tmp_path):
    p = tmp_path / "one.csv"
    p.write_text("t,s,feed,X\n0.0,0.0,0.0,1.5\n")
    with pytest.raises(PlanFileError, match="period"):
        read_csv(str(p))
    assert read_csv(str(p), dt_s=0.002).dt_s == 0.002


def test_atomic_write_success_and_failure(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_write(str(path)) as fh:
            fh.write(b"partial")
            raise RuntimeError("boom")
    assert path.read_bytes() == b"old"
    with pytest.raises(KeyboardInterrupt):
        with atomic_write(str(path)) as fh:
            fh.write(b"partial")
            raise KeyboardInterrupt
    assert path.read_bytes() == b"old"
    assert sorted(os.listdir(tmp_path)) == ["out.bin"]  # no temporary left behind
    with atomic_write(str(path)) as fh:
        fh.write(b"new")
    assert path.read_bytes() == b"new"
    assert sorted(os.listdir(tmp_path)) == ["out.bin"]
    mask = os.umask(0)
    os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask  # as open() would create it


def test_stdout_and_broken_pipe():
    # writing to stdout through atomic_write("-"); `| head -c` closes early
    code = (
        "import numpy as np\n"
        "from cnc_interp.plan.trajectory import Trajectory\n"
        "from cnc_interp.export.csv_io import write_csv\n"
        "k=200000\n"
        "tr=Trajectory('X',0.001,np.arange(k)*0.001,np.zeros(k),np.zeros(k),np.zeros((k,1)),"
        "np.zeros(k,int),'t')\n"
        "try:\n"
        "    write_csv(tr,'-')\n"
        "except BrokenPipeError:\n"
        "    import os, sys\n"
        "    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())\n"
        "    sys.exit(7)\n"
    )
    full = subprocess.run([sys.executable, "-c", code], capture_output=True, check=True)
    assert full.stdout.startswith(b"t,s,feed,X\n0.0,0.0,0.0,0.0\n0.001,")
    assert full.stdout.count(b"\n") == 200001
    proc = subprocess.run(
        f"'{sys.executable}' -c \"{code}\" | head -c 100 > /dev/null; echo ${{PIPESTATUS[0]}}",
        shell=True,
        executable="/bin/bash",
        capture_output=True,
        text=True,
    )
    assert proc.stdout.strip() == "7"  # BrokenPipeError reached the caller
    assert "Traceback" not in proc.stderr
