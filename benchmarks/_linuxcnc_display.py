"""A headless LinuxCNC display for ``benchmarks/linuxcnc.py``: runs one program and exits.

LinuxCNC starts it as ``DISPLAY`` (``PROGRAM -ini INIFILE``) once HAL runs; LinuxCNC shuts
itself down when it exits. It runs under the system python (``/usr/bin/python3``), which has
LinuxCNC's ``linuxcnc`` module. The INI's ``[CNC_INTERP_BENCH]`` section names the program
(``PROGRAM``), the ``halsampler`` output (``SAMPLES``), the result file (``RESULT``, JSON) and
a time limit (``TIMEOUT_S``). Steps: leave E-stop, machine on, home every joint (the INI homes
at once, in place), start ``halsampler`` and enable the ``sampler`` on the servo thread, open
and run the program in auto mode, resume any pause (M0, M60), wait until the interpreter is
idle with the motion queue empty and the machine in position, then stop the sampler.
"""

import json
import os
import signal
import subprocess
import sys
import time

# this folder holds benchmarks/linuxcnc.py, which would shadow LinuxCNC's module
sys.path = [p for p in sys.path if os.path.abspath(p or ".") != os.path.dirname(os.path.abspath(__file__))]
import linuxcnc  # noqa: E402

#: the display's poll period (s): a pause (M0) is resumed within about this long
POLL_S = 0.002
#: longest wait for LinuxCNC's task to answer at start, and for each setup command (s)
SETUP_TIMEOUT_S = 30.0
#: longest wait for the interpreter to leave idle after AUTO_RUN (s): a program with no
#: motion may finish between two polls
START_TIMEOUT_S = 5.0
#: the samples file not growing this long while the program runs means the servo thread
#: stopped (HAL is one per machine: another process's ``halrun -U`` unloads ours) (s)
STALL_S = 3.0
#: servo periods of rest recorded after the end, so the last move's end is in the samples (s)
TAIL_S = 0.3


def ini_value(path, section, key):
    sec = None
    with open(path) as fh:
        for raw in fh:
            line = raw.split("#", 1)[0].strip()
            if line.startswith("[") and line.endswith("]"):
                sec = line[1:-1]
            elif sec == section and "=" in line:
                k, v = line.split("=", 1)
                if k.strip() == key:
                    return v.strip()
    raise KeyError(f"[{section}] {key}")


def main():
    ini = sys.argv[sys.argv.index("-ini") + 1]
    program = ini_value(ini, "CNC_INTERP_BENCH", "PROGRAM")
    samples = ini_value(ini, "CNC_INTERP_BENCH", "SAMPLES")
    result_path = ini_value(ini, "CNC_INTERP_BENCH", "RESULT")
    timeout_s = float(ini_value(ini, "CNC_INTERP_BENCH", "TIMEOUT_S"))
    result = {"status": "error", "errors": [], "steps": []}
    sampler = None
    try:
        sampler = run(program, samples, timeout_s, result)
    except Exception as exc:  # recorded for the benchmark, which reports it
        result["errors"].append(f"{type(exc).__name__}: {exc}")
    finally:
        if sampler is not None and sampler.poll() is None:
            sampler.send_signal(signal.SIGINT)
            try:
                sampler.wait(10)
            except subprocess.TimeoutExpired:
                sampler.kill()
                sampler.wait()
        with open(result_path, "w") as fh:
            json.dump(result, fh)


def run(program, samples, timeout_s, result):
    s = linuxcnc.stat()
    c = linuxcnc.command()
    err = linuxcnc.error_channel()
    t0 = time.monotonic()
    while True:
        try:
            s.poll()
            break
        except linuxcnc.error:
            if time.monotonic() - t0 > SETUP_TIMEOUT_S:
                raise RuntimeError("LinuxCNC's task did not answer") from None
            time.sleep(0.1)

    def errors():
        while True:
            e = err.poll()
            if not e:
                return
            kind, text = e
            if kind in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
                result["errors"].append(text)
            else:
                result["steps"].append(f"message: {text}")

    def wait_for(cond, what, limit=SETUP_TIMEOUT_S):
        t = time.monotonic()
        while True:
            s.poll()
            errors()
            if cond():
                return
            if time.monotonic() - t > limit:
                raise RuntimeError(f"timed out waiting for {what}")
            time.sleep(0.01)

    c.state(linuxcnc.STATE_ESTOP_RESET)
    wait_for(lambda: s.task_state == linuxcnc.STATE_ESTOP_RESET, "E-stop reset")
    c.state(linuxcnc.STATE_ON)
    wait_for(lambda: s.task_state == linuxcnc.STATE_ON, "machine on")
    c.mode(linuxcnc.MODE_MANUAL)
    wait_for(lambda: s.task_mode == linuxcnc.MODE_MANUAL, "manual mode")
    c.home(-1)
    wait_for(lambda: all(s.homed[i] for i in range(s.joints)), "homing")
    result["steps"].append("homed")
    c.set_optional_stop(False)  # M1 does not pause
    c.mode(linuxcnc.MODE_AUTO)
    wait_for(lambda: s.task_mode == linuxcnc.MODE_AUTO, "auto mode")

    sampler = subprocess.Popen(["halsampler", "-t", samples], stderr=subprocess.PIPE)
    time.sleep(0.2)  # let halsampler attach before the sampler fills its FIFO
    subprocess.run(["halcmd", "setp", "sampler.0.enable", "1"], check=True)
    time.sleep(0.05)

    c.program_open(program)
    c.wait_complete(SETUP_TIMEOUT_S)
    errors()
    if result["errors"]:
        raise RuntimeError("the program did not open")
    t_run = time.monotonic()
    c.auto(linuxcnc.AUTO_RUN, 0)
    started = False
    size, grown = -1, time.monotonic()
    while True:
        s.poll()
        errors()
        if result["errors"]:
            c.abort()
            raise RuntimeError("LinuxCNC reported an error")
        running = s.interp_state != linuxcnc.INTERP_IDLE
        started = started or running
        if s.paused or s.interp_state == linuxcnc.INTERP_PAUSED:
            c.auto(linuxcnc.AUTO_RESUME)  # M0/M60: the benchmark counts no operator wait
        if not running and (started or time.monotonic() - t_run > START_TIMEOUT_S):
            if s.queue == 0 and s.inpos and s.exec_state == linuxcnc.EXEC_DONE:
                break
        now = time.monotonic()
        if os.path.getsize(samples) != size:
            size, grown = os.path.getsize(samples), now
        elif now - grown > STALL_S:
            c.abort()
            raise RuntimeError("servo thread stopped: no samples for %g s" % STALL_S)
        if time.monotonic() - t_run > timeout_s:
            c.abort()
            raise RuntimeError(f"the program did not finish within {timeout_s:g} s")
        time.sleep(POLL_S)
    result["wall_s"] = time.monotonic() - t_run
    time.sleep(TAIL_S)
    subprocess.run(["halcmd", "setp", "sampler.0.enable", "0"], check=True)
    overruns = subprocess.run(["halcmd", "getp", "sampler.0.overruns"], capture_output=True, text=True)
    result["overruns"] = overruns.stdout.strip()
    time.sleep(0.1)
    sampler.send_signal(signal.SIGINT)
    sampler.wait(10)
    result["status"] = "ok"
    return sampler


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
