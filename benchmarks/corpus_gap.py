"""How far the planners are from the discrete-time minimum on corpus geometry, weighted by
where the corpus cycle goes.

    .venv/bin/python benchmarks/corpus_gap.py                      # census, sample, oracle
    .venv/bin/python benchmarks/corpus_gap.py --count 24 --seed 1 --no-write
    .venv/bin/python benchmarks/corpus_gap.py --census-only        # the census table only

Every 3-axis corpus program (``plan.py``'s ``corpus_programs()`` that plan on the corpus
``configs/axis_mm.ini``, with ``plan.py``'s stand-in tool table, 1 ms, the default fit
tolerance) is planned with VPOp. Its samples split into rest-to-rest moving stretches (runs
of samples in which an axis moves, between standstills); the timeline plans each fitted path
from rest to rest, so each stretch is one path, found by its arc length along the program.
The census counts the cycle by kind of stretch: rapids, feed moves whose segments do not
all have one programmed feed, feed moves shorter than ``--min-steps`` or longer than
``--max-steps`` periods, the eligible rest, and the time at rest or in dwells.

From the eligible stretches (feed moves of one programmed feed, ``--min-steps`` ..
``--max-steps`` periods) ``--count`` are drawn with replacement, with probability
proportional to their VPOp duration (``--seed``), so the sample represents where the
eligible cycle goes. Each drawn program is planned again with the optimal planner; the fit
does not depend on the planner, so the stretch is the same path (checked: same path index,
arc length and end points). The oracle ``optimum_gap.py`` (``optimality.py``'s) computes
the least number of periods for the stretch's geometry (from the VPOp samples, with the
programmed feed and the INI's limits, jerk 10/s x amax where the INI has none); one run at
a time, each with ``--oracle-timeout``, a timeout counting as no result. Results are cached
in ``--cache``.

Estimates (drawn with probability proportional to the VPOp time T_v): the mean over the
draws of T_x / T_v estimates sum(T_x) / sum(T_v) over the eligible stretches, for T_x the
optimal planner's and the oracle's time, so the corpus-wide ratio of a planner to the
minimum is mean(T_planner / T_v) / mean(T_oracle / T_v) (draws with an oracle result).
The duration-weighted mean of the per-stretch ratios within the sample is printed as well;
it weights long stretches twice (once by the draw, once by the weight). The table goes to
``benchmarks/RESULTS.md`` ("Optimality on corpus stretches") unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from _results import command_line, md_table, write_section
from optimality import ORACLE, ORACLE_PYTHON, oracle_missing
from plan import CORPUS, corpus_programs, standin_tool_table

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

INI = os.path.join(CORPUS, "configs", "axis_mm.ini")
DT_S = 0.001
#: relative tolerance on the programmed feed for "one feed" within a path
FEED_REL = 1e-9


def machine_toml(machine) -> str:
    """The oracle's machine file: the loaded machine's limits (the INI's, with its defaults)."""
    out = [f'name = "{machine.name}"', f"dt = {machine.dt_s!r}", f'kinematics = "{machine.kinematics}"']
    for i, a in enumerate(machine.axes):
        out += [
            f"[axes.{a}]",
            f"vmax = {float(machine.vmax[i])!r}",
            f"amax = {float(machine.amax[i])!r}",
            f"jmax = {float(machine.jmax[i])!r}",
        ]
    return "\n".join(out) + "\n"


def _plan(path: str, planner: str, tool_table: str):
    from cnc_interp.pipeline import plan_part

    return plan_part(path, INI, planner, DT_S, tool_table=tool_table)


def moving_runs(q: np.ndarray) -> list[tuple[int, int]]:
    """(I, J) of each rest-to-rest moving run: I the last sample at the start point, J the
    first at the end point (J - I periods)."""
    moving = np.any(q[1:] != q[:-1], axis=1)
    if not moving.any():
        return []
    d = np.diff(np.concatenate(([0], moving.astype(np.int8), [0])))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)
    return [(int(a), int(b)) for a, b in zip(starts, ends)]


def stretches(out, program: str) -> list[dict]:
    """The plan's moving runs, each matched to its fitted path by arc length."""
    traj = out.trajectory
    paths = out.fit.paths
    s0 = np.concatenate(([0.0], np.cumsum([p.length for p in paths])))
    recs = []
    for a, b in moving_runs(traj.q):
        sa, sb = float(traj.s[a]), float(traj.s[b])
        k = int(np.searchsorted(s0, 0.5 * (sa + sb), side="right") - 1)
        k = min(max(k, 0), len(paths) - 1)
        p = paths[k]
        scale = max(1.0, p.length)
        matched = abs(sa - s0[k]) <= 1e-6 * scale and abs(sb - s0[k + 1]) <= 1e-6 * scale
        feeds = np.asarray(p.feed_mm_s, dtype=float)
        one_feed = bool(np.all(np.isfinite(feeds))) and float(feeds.max() - feeds.min()) <= FEED_REL * float(
            feeds.max()
        )
        recs.append(
            {
                "program": program,
                "from": a,
                "to": b,
                "N": b - a,
                "path": k,
                "length_mm": float(p.length),
                "rapid": bool(p.rapid),
                "matched": bool(matched),
                "one_feed": one_feed,
                "feed_mm_min": float(feeds.max()) * 60.0 if one_feed else None,
                "start": [float(v) for v in traj.q[a]],
                "end": [float(v) for v in traj.q[b]],
            }
        )
    return recs


def kind(st: dict, bands: list[tuple[int, int, int]]) -> str:
    """The census bucket of a stretch: rapid, not one feed, a band ``lo-hi`` or another length."""
    if st["rapid"]:
        return "rapid"
    if not st["matched"]:
        return "unmatched"
    if not st["one_feed"]:
        return "feed changes"
    for lo, hi, _ in bands:
        if lo <= st["N"] <= hi:
            return f"{lo}-{hi}"
    return "other length"


def parse_bands(text: str) -> list[tuple[int, int, int]]:
    """``LO-HI:COUNT,...`` -> [(lo, hi, count)]."""
    out = []
    for part in text.split(","):
        rng, _, cnt = part.partition(":")
        lo, _, hi = rng.partition("-")
        out.append((int(lo), int(hi), int(cnt)))
    return out


def census(tool_table: str, cache_path: str, refresh: bool) -> dict:
    """Plan every 3-axis corpus program with VPOp; its stretches and cycle. Cached on the
    program files' sizes and modification times and this checkout's commit."""
    from _results import commit

    files = corpus_programs()
    sig = hashlib.sha256()
    for f in files:
        st = os.stat(f)
        sig.update(f"{f}:{st.st_size}:{st.st_mtime_ns}".encode())
    sig.update(commit().encode())
    key = sig.hexdigest()[:20]
    if not refresh:
        try:
            with open(cache_path) as fh:
                data = json.load(fh)
            if data.get("key") == key:
                print(f"census: cached ({cache_path})", flush=True)
                return data
        except (OSError, ValueError):
            pass
    from cnc_interp.errors import CncInterpError

    programs, skipped = [], []
    t0 = time.perf_counter()
    for f in files:
        rel = os.path.relpath(f, CORPUS)
        try:
            out = _plan(f, "vpop", tool_table)
        except CncInterpError as exc:
            skipped.append({"program": rel, "why": exc.format().strip().splitlines()[0][:120]})
            continue
        traj = out.trajectory
        programs.append({"program": rel, "cycle_s": traj.duration_s, "stretches": stretches(out, rel)})
        print(f"  {rel:56s} cycle {traj.duration_s:9.2f} s  {len(programs[-1]['stretches'])} stretches", flush=True)
    data = {"key": key, "programs": programs, "skipped": skipped, "wall_s": time.perf_counter() - t0}
    os.makedirs(os.path.dirname(cache_path), exist_ok=True)
    with open(cache_path, "w") as fh:
        json.dump(data, fh)
    return data


def _write_slice(traj, a: int, b: int, path: str, pad: int = 3) -> tuple[int, int]:
    """Samples a-pad .. b+pad of ``traj`` as a plan CSV; returns (a, b) as rows of the file."""
    from cnc_interp.export.csv_io import CsvPlanWriter

    lo, hi = max(0, a - pad), min(traj.n_samples, b + pad + 1)
    with open(path, "wb") as fh:
        w = CsvPlanWriter(fh, traj.axes)
        w.write(traj.t[lo:hi], traj.s[lo:hi], traj.feed[lo:hi], traj.q[lo:hi])
    return a - lo, b - lo


def _oracle(csv: str, toml: str, feed_mm_min: float, a: int, b: int, timeout: float) -> dict:
    cmd = [ORACLE_PYTHON, ORACLE, csv, toml, "--feed", repr(feed_mm_min), "--dt", repr(DT_S)]
    cmd += ["--from-index", str(a), "--to-index", str(b), "--json"]
    t0 = time.perf_counter()
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:g} s"}
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        tail = (res.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": f"exit {res.returncode}: {tail[:160]}", "wall_s": wall}
    d = json.loads(res.stdout)
    return {
        "N": d["optimum"]["N"],
        "verified": d["optimum"]["verify"]["ok"],
        "N_minus_1_tau": (d["optimum"].get("N_minus_1") or {}).get("tau"),
        "plan_N": d["plan"]["N"],
        "plan_worst_is": d["plan"]["worst_is"],
        "plan_axes": d["plan"]["axes"],
        "plan_feed": d["plan"]["feed"],
        "opt_worst_is": d["optimum"]["verify"].get("worst_is"),
        "opt_feed": d["optimum"]["verify"].get("feed"),
        "opt_axes": d["optimum"]["verify"].get("axes"),
        "midpoint_err": d["geometry"]["midpoint_err"],
        "holdout_err": d["geometry"]["holdout_err"],
        "warnings": d.get("warnings", []),
        "wall_s": wall,
    }


def _step_ratios(q: np.ndarray, a: int, b: int, machine, feed_mm_s: float) -> dict:
    """Worst V/A/J ratio per axis and feed ratio of samples a..b (rest padding outside)."""
    seg = q[a : b + 1]
    pad = np.concatenate([np.repeat(seg[:1], 3, axis=0), seg, np.repeat(seg[-1:], 3, axis=0)])
    dt = DT_S
    v = np.diff(pad, axis=0) / dt
    acc = np.diff(pad, 2, axis=0) / dt**2
    j = np.diff(pad, 3, axis=0) / dt**3
    out = {}
    for i, ax in enumerate(machine.axes):
        out[ax] = [
            float(np.abs(v[:, i]).max() / machine.vmax[i]),
            float(np.abs(acc[:, i]).max() / machine.amax[i]),
            float(np.abs(j[:, i]).max() / machine.jmax[i]),
        ]
    speed = np.linalg.norm(np.diff(seg, axis=0), axis=1) / dt
    out["feed"] = float(speed.max() / feed_mm_s)
    # share of periods within 0.5 % of the feed, or of any axis's vmax
    vel = np.abs(np.diff(seg, axis=0)) / dt
    at_v = np.any(vel >= 0.995 * machine.vmax, axis=1) | (speed >= 0.995 * feed_mm_s)
    out["cruise_share"] = float(at_v.mean()) if at_v.size else 0.0
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--bands",
        default="200-6000:24,10-199:24",
        help="LO-HI:COUNT,...: stretch lengths in periods and the draws from each (default %(default)s)",
    )
    ap.add_argument("--count", type=int, default=None, help="draws per band (overrides the bands' counts)")
    ap.add_argument("--oracle-timeout", type=float, default=300.0)
    ap.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "cnc-interp", "corpus_gap.json"))
    ap.add_argument("--refresh-census", action="store_true", help="plan the corpus again even if cached")
    ap.add_argument("--census-only", action="store_true", help="the census, no sample, no oracle")
    ap.add_argument("--no-oracle", action="store_true", help="cached oracle results only")
    ap.add_argument("--json", default=None, help="write the census, the draws and the estimates here")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    bands = parse_bands(args.bands)
    if args.count is not None:
        bands = [(lo, hi, args.count) for lo, hi, _ in bands]

    from cnc_interp.machine.load import load_machine

    machine = load_machine(INI)
    with tempfile.TemporaryDirectory(prefix="cnc-gap-") as work:
        tool_table = standin_tool_table(work)
        cen = census(tool_table, args.cache.replace(".json", ".census.json"), args.refresh_census)
        total_cycle = sum(p["cycle_s"] for p in cen["programs"])
        by_kind: dict[str, list] = {}
        pool: dict[str, list] = {f"{lo}-{hi}": [] for lo, hi, _ in bands}
        prog_time: dict[str, dict[str, float]] = {}
        for p in cen["programs"]:
            for st in p["stretches"]:
                k = kind(st, bands)
                c = by_kind.setdefault(k, [0, 0.0])
                c[0] += 1
                c[1] += st["N"] * DT_S
                if k in pool:
                    pool[k].append(st)
                    pt = prog_time.setdefault(k, {})
                    pt[st["program"]] = pt.get(st["program"], 0.0) + st["N"] * DT_S
        moving = sum(c[1] for c in by_kind.values())
        by_kind["at rest / dwell"] = [0, total_cycle - moving]
        census_rows = []
        for k, (n, t) in sorted(by_kind.items(), key=lambda kv: -kv[1][1]):
            top = ""
            if k in prog_time:
                name, secs = max(prog_time[k].items(), key=lambda kv: kv[1])
                top = f"{name} {100.0 * secs / t:.0f} %"
            label = f"feed moves, one feed, {k} periods" if k in pool else k
            census_rows.append([label, n, f"{t:,.1f}", f"{100.0 * t / total_cycle:.1f} %", top])
        census_table = md_table(
            ["stretches (VPOp)", "count", "time s", "share of cycle", "largest program in it"], census_rows
        )
        print(
            f"census: {len(cen['programs'])} programs planned on axis_mm.ini, {len(cen['skipped'])} skipped, "
            f"cycle {total_cycle:,.1f} s"
        )
        print(census_table, flush=True)
        if args.census_only:
            return

        rng = np.random.default_rng(args.seed)
        draws = []  # (band, stretch)
        for lo, hi, cnt in bands:
            cand = pool[f"{lo}-{hi}"]
            if not cand or cnt <= 0:
                continue
            w = np.array([st["N"] for st in cand], dtype=float)
            for i in rng.choice(len(cand), size=cnt, replace=True, p=w / w.sum()):
                draws.append((f"{lo}-{hi}", cand[int(i)]))
        missing = None if args.no_oracle else oracle_missing()
        if missing:
            print(f"no oracle: {missing}; cached results only", flush=True)
        try:
            with open(args.cache) as fh:
                ocache = json.load(fh)
        except (OSError, ValueError):
            ocache = {}
        toml = os.path.join(work, "axis_mm.toml")
        with open(toml, "w") as fh:
            fh.write(machine_toml(machine))
        uniq: dict[tuple[str, int], dict] = {}
        for _, st in draws:
            uniq.setdefault((st["program"], st["path"]), st)
        by_prog: dict[str, list[dict]] = {}
        for st in uniq.values():
            by_prog.setdefault(st["program"], []).append(st)
        todo = []
        for prog, sts in by_prog.items():
            f = os.path.join(CORPUS, prog)
            vp = _plan(f, "vpop", tool_table)
            op = _plan(f, "optimal", tool_table)
            v_by_path = {s["path"]: s for s in stretches(vp, prog)}
            o_by_path = {s["path"]: s for s in stretches(op, prog)}
            for st in sts:
                v = v_by_path[st["path"]]
                o = o_by_path.get(st["path"])
                same = (
                    o is not None
                    and abs(o["length_mm"] - v["length_mm"]) <= 1e-9 * max(1.0, v["length_mm"])
                    and np.allclose(o["start"], v["start"], atol=1e-9)
                    and np.allclose(o["end"], v["end"], atol=1e-9)
                )
                feed_s = st["feed_mm_min"] / 60.0
                rec = {
                    **{k: st[k] for k in ("program", "path", "length_mm", "feed_mm_min")},
                    "vpop": {"from": v["from"], "to": v["to"], "N": v["N"]},
                    "optimal": {"from": o["from"], "to": o["to"], "N": o["N"]} if o else None,
                    "same_geometry": bool(same),
                    "vpop_ratios": _step_ratios(vp.trajectory.q, v["from"], v["to"], machine, feed_s),
                    "optimal_ratios": _step_ratios(op.trajectory.q, o["from"], o["to"], machine, feed_s) if o else None,
                }
                key = hashlib.sha256(
                    f"{st['program']}|{st['path']}|{st['length_mm']:.9f}|{st['feed_mm_min']!r}|{v['N']}".encode()
                ).hexdigest()[:20]
                csv = os.path.join(work, f"{len(todo)}.csv")
                a, b = _write_slice(vp.trajectory, v["from"], v["to"], csv)
                todo.append((rec, key, csv, a, b))
            del vp, op
        todo.sort(key=lambda x: x[0]["vpop"]["N"])
        results: dict[tuple[str, int], dict] = {}
        for rec, key, csv, a, b in todo:
            if key not in ocache and not missing and not args.no_oracle:
                print(
                    f"  oracle {rec['program']} path {rec['path']} samples {rec['vpop']['from']}..{rec['vpop']['to']}"
                    f" ({rec['vpop']['N']} periods) F{rec['feed_mm_min']:g} ...",
                    end="",
                    flush=True,
                )
                res = _oracle(csv, toml, rec["feed_mm_min"], a, b, args.oracle_timeout)
                print(f" {res.get('N', res.get('error'))} ({res.get('wall_s', args.oracle_timeout):.0f} s)", flush=True)
                if "Error:" not in res.get("error", ""):
                    ocache[key] = res  # a result, a timeout or a refusal; a crash is retried
                rec["oracle"] = res
                os.makedirs(os.path.dirname(args.cache), exist_ok=True)
                with open(args.cache, "w") as fh:
                    json.dump(ocache, fh, indent=1, sort_keys=True)
            rec["oracle"] = ocache.get(key, rec.get("oracle"))
            results[(rec["program"], rec["path"])] = rec

    rows = [{"band": band, **results[(st["program"], st["path"])]} for band, st in draws]
    band_time = {k: by_kind.get(k, [0, 0.0])[1] for k in pool}
    summary = _summary(rows, band_time, total_cycle)
    summary["fallback"] = _summary(rows, band_time, total_cycle, fallback=True)
    _print(rows, summary)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {"census": by_kind, "total_cycle_s": total_cycle, "draws": rows, "summary": summary}, fh, indent=1
            )
    if not args.no_write:
        write_section(
            "Optimality on corpus stretches",
            "corpus_gap.py",
            command_line("corpus_gap.py", argv),
            census_table + "\n\n" + _markdown(rows) + "\n\n" + _summary_table(summary),
            _notes(summary, len(cen["programs"]), total_cycle, args),
        )


def _oracle_n(rec: dict, fallback: bool = False) -> int | None:
    """The least periods known for the stretch: the oracle's verified N, or a planner's N when
    that is fewer (the oracle is a local solver; a plan that passed verification is feasible).
    Without an oracle result: None, or with ``fallback`` the best planner's N (an upper bound
    of the minimum, so the gap it gives is a lower bound)."""
    o = rec.get("oracle") or {}
    plans = [rec["vpop"]["N"]] + ([rec["optimal"]["N"]] if rec.get("optimal") and rec["same_geometry"] else [])
    if not o.get("verified"):
        return min(plans) if fallback else None
    return min([o["N"], *plans])


def _oracle_stuck(rec: dict) -> bool:
    o = rec.get("oracle") or {}
    return bool(o.get("verified")) and o["N"] > (_oracle_n(rec) or o["N"])


def _estimate(ok: list[dict], fallback: bool) -> dict:
    """mean(T_x / T_VPOp) over draws made with probability proportional to T_VPOp."""
    tv = np.array([r["vpop"]["N"] for r in ok], float)
    to = np.array([r["optimal"]["N"] for r in ok], float)
    tm = np.array([float(_oracle_n(r, fallback)) for r in ok])
    return {
        "n": len(ok),
        "m_opt": float(np.mean(to / tv)),
        "m_min": float(np.mean(tm / tv)),
        "w_vpop": float(np.sum(tv * (tv / tm)) / np.sum(tv)),
        "w_opt": float(np.sum(tv * (to / tm)) / np.sum(tv)),
        "_arrays": (tv, to, tm),
    }


def _summary(rows: list[dict], band_time: dict[str, float], total_cycle: float, fallback: bool = False) -> dict:
    """Per band and over the bands (each band's estimate weighted by its VPOp time):
    sum(T) / sum(T_min) for VPOp and the optimal planner, with 90 % bootstrap intervals."""
    out: dict = {"bands": {}}
    per = {}
    for band in band_time:
        ok = [r for r in rows if r["band"] == band and _oracle_n(r, fallback) and r["optimal"] and r["same_geometry"]]
        drawn = sum(1 for r in rows if r["band"] == band)
        if not ok:
            out["bands"][band] = {"draws": drawn, "with_oracle": 0, "time_s": band_time[band]}
            continue
        e = _estimate(ok, fallback)
        per[band] = e
        out["bands"][band] = {
            "draws": drawn,
            "with_oracle": e["n"],
            "time_s": band_time[band],
            "vpop_over_min": 1.0 / e["m_min"],
            "optimal_over_min": e["m_opt"] / e["m_min"],
            "optimal_over_vpop": e["m_opt"],
            "vpop_ratio_weighted_in_sample": e["w_vpop"],
            "optimal_ratio_weighted_in_sample": e["w_opt"],
        }
    if not per:
        return out
    rng = np.random.default_rng(0)

    def combine(sel) -> tuple[float, float, float]:
        tv_tot = sum(band_time[b] for b in per)
        t_opt = sum(band_time[b] * np.mean(per[b]["_arrays"][1][sel[b]] / per[b]["_arrays"][0][sel[b]]) for b in per)
        t_min = sum(band_time[b] * np.mean(per[b]["_arrays"][2][sel[b]] / per[b]["_arrays"][0][sel[b]]) for b in per)
        return tv_tot / t_min, t_opt / t_min, t_opt / tv_tot

    full = {b: np.arange(per[b]["n"]) for b in per}
    v, o, ov = combine(full)
    bs = [combine({b: rng.integers(0, per[b]["n"], per[b]["n"]) for b in per}) for _ in range(2000)]
    bs = np.array(bs)
    t_bands = sum(band_time[b] for b in per)
    out["all"] = {
        "bands": sorted(per),
        "share_of_cycle": t_bands / total_cycle,
        # the cycle saved against VPOp if the bands' stretches ran at the minimum / as the optimal planner runs them
        "saving_at_min_of_cycle": (t_bands - t_bands / v) / total_cycle,
        "saving_optimal_of_cycle": (t_bands - t_bands * ov) / total_cycle,
        "time_s": sum(band_time[b] for b in per),
        "vpop_over_min": v,
        "optimal_over_min": o,
        "optimal_over_vpop": ov,
        "vpop_over_min_90": [float(np.percentile(bs[:, 0], 5)), float(np.percentile(bs[:, 0], 95))],
        "optimal_over_min_90": [float(np.percentile(bs[:, 1], 5)), float(np.percentile(bs[:, 1], 95))],
    }
    for b in per:
        sel = {k: full[k] for k in per}
        boot = []
        for _ in range(2000):
            sel[b] = rng.integers(0, per[b]["n"], per[b]["n"])
            tv, to, tm = (x[sel[b]] for x in per[b]["_arrays"])
            mm = np.mean(tm / tv)
            boot.append((1.0 / mm, np.mean(to / tv) / mm))
        boot = np.array(boot)
        out["bands"][b]["vpop_over_min_90"] = [
            float(np.percentile(boot[:, 0], 5)),
            float(np.percentile(boot[:, 0], 95)),
        ]
        out["bands"][b]["optimal_over_min_90"] = [
            float(np.percentile(boot[:, 1], 5)),
            float(np.percentile(boot[:, 1], 95)),
        ]
    return out


def _min_binds(r: dict) -> str:
    """The limits the oracle's minimum reaches (ratio >= 0.9: with N whole, a short stretch's minimum
    keeps some slack)."""
    o = r.get("oracle") or {}
    tags = ["F"] if (o.get("opt_feed") or 0) >= 0.9 else []
    for ax, vals in (o.get("opt_axes") or {}).items():
        tags += [f"{ax}{name}" for name, x in zip("VAJ", vals) if x >= 0.9]
    return " ".join(tags) or "-"


def _binds(r: dict, planner: str) -> str:
    """The limits the plan reaches (ratio >= 0.99) and its share of periods at cruise."""
    rat = r.get(f"{planner}_ratios") or {}
    tags = []
    if rat.get("feed", 0) >= 0.99:
        tags.append("F")
    for ax, vals in rat.items():
        if ax in ("feed", "cruise_share"):
            continue
        for name, x in zip("VAJ", vals):
            if x >= 0.99:
                tags.append(f"{ax}{name}")
    share = rat.get("cruise_share")
    return (" ".join(tags) or "-") + (f"; cruise {100 * share:.0f} %" if share is not None else "")


HEADER = [
    "#",
    "band",
    "program",
    "VPOp samples",
    "T s",
    "F mm/min",
    "L mm",
    "VPOp N",
    "optimal N",
    "oracle N",
    "VPOp / min",
    "optimal / min",
    "VPOp at limit",
    "minimum at limit",
]


def _table_rows(rows: list[dict]) -> list[list]:
    out = []
    for n, r in enumerate(rows, 1):
        o = r.get("oracle") or {}
        on = _oracle_n(r)
        opn = r["optimal"]["N"] if r["optimal"] else None
        if on:
            cell = f"{o['N']} (stuck; min {on} from a plan)" if _oracle_stuck(r) else on
        elif not o:
            cell = "-"
        else:
            cell = "unverified" if "N" in o else o.get("error", "?")[:40]
        out.append(
            [
                n,
                r["band"],
                r["program"],
                f"{r['vpop']['from']}..{r['vpop']['to']}",
                f"{r['vpop']['N'] * DT_S:.3f}",
                f"{r['feed_mm_min']:g}",
                f"{r['length_mm']:.2f}",
                r["vpop"]["N"],
                (opn if opn is not None else "-") if r["same_geometry"] else f"{opn} (geometry differs)",
                cell,
                f"{r['vpop']['N'] / on:.4f}" if on else "-",
                f"{opn / on:.4f}" if on and opn else "-",
                _binds(r, "vpop"),
                _min_binds(r) if on else "-",
            ]
        )
    return out


def _markdown(rows: list[dict]) -> str:
    return md_table(HEADER, _table_rows(rows))


def _summary_table(s: dict) -> str:
    def ci(x) -> str:
        return f"{x[0]:.4f}..{x[1]:.4f}" if x else "-"

    rows = []
    for b, e in s["bands"].items():
        if not e.get("with_oracle"):
            rows.append([b, f"{e['time_s']:,.1f}", f"0/{e['draws']}", "-", "-", "-", "-"])
            continue
        rows.append(
            [
                b,
                f"{e['time_s']:,.1f}",
                f"{e['with_oracle']}/{e['draws']}",
                f"{e['vpop_over_min']:.4f} ({ci(e['vpop_over_min_90'])})",
                f"{e['optimal_over_min']:.4f} ({ci(e['optimal_over_min_90'])})",
                f"{e['optimal_over_vpop']:.4f}",
                f"{e['vpop_ratio_weighted_in_sample']:.4f} / {e['optimal_ratio_weighted_in_sample']:.4f}",
            ]
        )
    together = (("bands together", s), ("bands together, no-result draws at the best plan's N", s.get("fallback")))
    for label, src in together:
        if not src or "all" not in src:
            continue
        a = src["all"]
        rows.append(
            [
                label,
                f"{a['time_s']:,.1f}",
                "",
                f"{a['vpop_over_min']:.4f} ({ci(a['vpop_over_min_90'])})",
                f"{a['optimal_over_min']:.4f} ({ci(a['optimal_over_min_90'])})",
                f"{a['optimal_over_vpop']:.4f}",
                "",
            ]
        )
    return md_table(
        [
            "band (periods)",
            "VPOp time s",
            "draws with oracle",
            "VPOp / min (90 %)",
            "optimal / min (90 %)",
            "optimal / VPOp",
            "in-sample duration-weighted ratio VPOp / optimal",
        ],
        rows,
    )


def _notes(s: dict, n_prog: int, cycle: float, args) -> str:
    return (
        f"{n_prog} programs planned on axis_mm.ini (jerk 10/s x amax), stand-in tool table, 1 ms, default fit "
        f"tolerance. First table: VPOp's cycle ({cycle:,.1f} s) by kind of rest-to-rest stretch. Second: the "
        f"draws (seed {args.seed}, with replacement, probability proportional to VPOp time within each band; a "
        "stretch drawn twice is listed twice); N in periods; oracle `optimum_gap.py` (timeout "
        f"{args.oracle_timeout:g} s) on VPOp's samples of the stretch. 'VPOp at limit': the limits VPOp's samples "
        "reach (>= 99 %: F feed, XV/XA/XJ an axis's velocity, acceleration, jerk) and its share of periods at "
        "the feed or an axis's vmax. Third: the estimates of sum(T) / sum(T_min) over each band's stretches "
        "(1 / mean(T_min / T_VPOp) and mean(T_opt / T_VPOp) / mean(T_min / T_VPOp) over the draws), bands "
        "together weighted by their VPOp time; 90 % intervals from a bootstrap over the draws. The in-sample "
        "duration-weighted mean of the per-stretch ratios weights long stretches twice (draw and weight). "
        "'minimum': the oracle's verified N, or a planner's N where the oracle stopped above it (marked 'stuck'); "
        "'minimum at limit': the limits the oracle's solution reaches (>= 90 %).\n\n" + _saving_line(s)
    )


def _saving_line(s: dict) -> str:
    a = s.get("all")
    if not a:
        return ""
    return (
        f"The bands carry {100 * a['share_of_cycle']:.1f} % of VPOp's corpus cycle. Run at the minimum, their "
        f"stretches would save {100 * a['saving_at_min_of_cycle']:.2f} % of the corpus cycle against VPOp; the "
        f"optimal planner saves {100 * a['saving_optimal_of_cycle']:.2f} % there"
        + (
            f" (draws without an oracle result at the best plan's N: {100 * f['saving_at_min_of_cycle']:.2f} % and "
            f"{100 * f['saving_optimal_of_cycle']:.2f} %)."
            if (f := (s.get("fallback") or {}).get("all"))
            else "."
        )
    )


def _print(rows: list[dict], s: dict) -> None:
    print(md_table(HEADER, _table_rows(rows)))
    print()
    print(_summary_table(s))
    print(_saving_line(s))


if __name__ == "__main__":
    main()
