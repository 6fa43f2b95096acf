"""The command line: every command's --help, verify/plot exit codes, atomic outputs."""

from __future__ import annotations

import json
import os
import sys

import pytest
from click.testing import CliRunner

from cnc_interp import cli
from cnc_interp.errors import CncInterpError
from cnc_interp.outfile import atomic_write
from cnc_interp.export.csv_io import write_csv
from cnc_interp.export.mcap_io import write_mcap

from ._export_synth import arc_trajectory, machine_for, machine_toml


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    traj = arc_trajectory(duration_s=1.0)
    good = machine_for(traj, 1.25, name="roomy")
    tight = machine_for(traj, 0.9, name="tight")
    (d / "good.toml").write_text(machine_toml(good))
    (d / "tight.toml").write_text(machine_toml(tight))
    (d / "bad.toml").write_text('name = "broken"\n[axes.X]\nvmax = -5\n')
    write_csv(traj, str(d / "plan.csv"))
    write_mcap(traj, str(d / "plan.mcap"), None, good)
    return d


def _run_cli(monkeypatch, capsys, *args) -> tuple[int, str, str]:
    """Run the installed entry point (with its error-to-exit-code mapping) in-process."""
    monkeypatch.setattr(sys, "argv", ["cnc-interp", *args])
    with pytest.raises(SystemExit) as ei:
        cli.run()
        sys.exit(0)
    out, err = capsys.readouterr()
    return ei.value.code or 0, out, err


@pytest.mark.parametrize("command", sorted(cli.main.commands))
def test_every_command_help(command):
    result = CliRunner().invoke(cli.main, [command, "--help"])
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.output


def test_top_level_help_and_version():
    runner = CliRunner()
    assert runner.invoke(cli.main, ["--help"]).exit_code == 0
    res = runner.invoke(cli.main, ["--version"])
    assert res.exit_code == 0 and cli.__version__ in res.output


@pytest.mark.parametrize("plan", ["plan.csv", "plan.mcap"])
def test_verify_good_plan_exits_0(files, plan):
    res = CliRunner().invoke(cli.main, ["verify", str(files / plan), "-m", str(files / "good.toml")])
    assert res.exit_code == 0, res.output
    assert "ok" in res.output


@pytest.mark.parametrize("plan", ["plan.csv", "plan.mcap"])
def test_verify_violating_plan_exits_1(files, plan):
    res = CliRunner().invoke(cli.main, ["verify", str(files / plan), "-m", str(files / "tight.toml"), "--json"])
    assert res.exit_code == 1
    report = json.loads(res.output)
    assert report["ok"] is False
    assert report["worst_ratio"] == pytest.approx(1 / 0.9, rel=1e-9)


def test_verify_json_good(files):
    res = CliRunner().invoke(cli.main, ["verify", str(files / "plan.csv"), "-m", str(files / "good.toml"), "--json"])
    assert res.exit_code == 0
    report = json.loads(res.output)
    assert report["ok"] is True and report["worst_ratio"] == pytest.approx(0.8, rel=1e-9)
    assert set(report["axes"]) == {"X", "Y", "Z"}


def test_verify_bad_machine_exits_2(files, monkeypatch, capsys):
    code, out, err = _run_cli(monkeypatch, capsys, "verify", str(files / "plan.csv"), "-m", str(files / "bad.toml"))
    assert code == 2
    assert "bad.toml" in err and "error:" in err and "Traceback" not in err
    code, _, err = _run_cli(monkeypatch, capsys, "verify", str(files / "plan.csv"), "-m", "no-such-preset")
    assert code == 2 and "error:" in err


def test_verify_exit_codes_through_entry_point(files, monkeypatch, capsys):
    assert _run_cli(monkeypatch, capsys, "verify", str(files / "plan.mcap"), "-m", str(files / "good.toml"))[0] == 0
    assert _run_cli(monkeypatch, capsys, "verify", str(files / "plan.mcap"), "-m", str(files / "tight.toml"))[0] == 1
    # a file that is not a plan is bad input, not a crash
    junk = files / "junk.csv"
    junk.write_text("hello,world\n1,2\n")
    code, _, err = _run_cli(monkeypatch, capsys, "verify", str(junk), "-m", str(files / "good.toml"))
    assert code == 2 and "junk.csv" in err and "Traceback" not in err
    # a CSV without -m is checked against the default preset, as `plan` plans without -m
    code, out, _ = _run_cli(monkeypatch, capsys, "verify", str(files / "plan.csv"))
    assert code in (0, 1) and "(preset:generic-mill, default)" in out


def test_plot_command(files, tmp_path):
    out = tmp_path / "fig.png"
    res = CliRunner().invoke(
        cli.main, ["plot", str(files / "plan.mcap"), "-m", str(files / "good.toml"), "-o", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert res.output.strip() == str(out)
    assert out.stat().st_size > 20_000


def test_plot_bad_machine_exits_2(files, monkeypatch, capsys, tmp_path):
    out = tmp_path / "fig.png"
    code, _, err = _run_cli(
        monkeypatch, capsys, "plot", str(files / "plan.csv"), "-m", str(files / "bad.toml"), "-o", str(out)
    )
    assert code == 2 and not out.exists()


def test_plot_unknown_image_format_exits_2(files, monkeypatch, capsys, tmp_path):
    out = tmp_path / "fig.xyz"
    code, _, err = _run_cli(monkeypatch, capsys, "plot", str(files / "plan.csv"), "-o", str(out))
    assert code == 2 and "fig.xyz" in err and "png" in err and not out.exists()


def test_exception_mid_write_leaves_no_file(tmp_path):
    target = tmp_path / "out.csv"
    with pytest.raises(RuntimeError):
        with atomic_write(str(target)) as fh:
            fh.write(b"t,s,feed,X\n0.0,0.0,0.0,1.0\n")
            raise RuntimeError("disk on fire")
    assert os.listdir(tmp_path) == []


def test_ctrl_c_mid_write_keeps_previous_file(tmp_path):
    target = tmp_path / "out.mcap"
    target.write_bytes(b"previous")
    with pytest.raises(KeyboardInterrupt):
        with atomic_write(str(target)) as fh:
            fh.write(b"partial")
            raise KeyboardInterrupt
    assert target.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["out.mcap"]


def test_ctrl_c_during_csv_and_mcap_writers(tmp_path, monkeypatch):
    """Interrupt the real writers part-way through: no output, no temporary file."""
    import cnc_interp.export.mcap_io as mio

    traj = arc_trajectory(duration_s=0.5)
    calls = {"n": 0}
    real = mio._pack_rows

    def interrupted(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 1:  # the first batch is formatted and written, then Ctrl-C
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(mio, "_pack_rows", interrupted)
    monkeypatch.setattr(mio, "_BATCH", 100)
    with pytest.raises(KeyboardInterrupt):
        write_mcap(traj, str(tmp_path / "p.mcap"), None, None)
    assert calls["n"] == 2
    assert os.listdir(tmp_path) == []


def test_outputs_byte_identical(tmp_path):
    traj = arc_trajectory(duration_s=0.3)
    machine = machine_for(traj, 1.5)
    for ext in ("csv", "mcap"):
        paths = [str(tmp_path / f"{i}.{ext}") for i in range(2)]
        for p in paths:
            if ext == "csv":
                write_csv(arc_trajectory(duration_s=0.3), p)
            else:
                write_mcap(arc_trajectory(duration_s=0.3), p, {"input": {"name": "x"}}, machine)
        assert open(paths[0], "rb").read() == open(paths[1], "rb").read()


def test_error_is_cnc_interp_error_under_clirunner(files):
    res = CliRunner().invoke(cli.main, ["verify", str(files / "plan.csv"), "-m", str(files / "bad.toml")])
    assert isinstance(res.exception, CncInterpError) and res.exception.exit_code == 2


@pytest.mark.parametrize("wrapped", [True, False])
def test_interrupt_inside_compiled_code_is_ctrl_c(monkeypatch, capsys, wrapped):
    """Ctrl-C that lands while a numba function returns surfaces as a SystemError caused by
    the KeyboardInterrupt: still exit 130 and one 'interrupted' line, not an internal error.
    A SystemError without that cause stays an internal error."""

    def fake_main(*args, **kwargs):
        if wrapped:
            raise SystemError(
                "CPUDispatcher(<function refine>) returned a result with an exception set"
            ) from KeyboardInterrupt()
        raise SystemError("something else")

    monkeypatch.setattr(cli.main, "main", fake_main)
    monkeypatch.delenv("CNC_INTERP_DEBUG", raising=False)
    with pytest.raises(SystemExit) as ei:
        cli.run()
    err = capsys.readouterr().err
    if wrapped:
        assert ei.value.code == 130 and err == "cnc-interp: interrupted\n", err
    else:
        assert ei.value.code == 1 and "internal error: SystemError" in err, err
