"""The Markdown and the figure of ``benchmarks/verdict.py``, made from its records.

The acceptance table of issue 17, the counts per set, the ambiguous and cue pairs one by one,
the flagged normal pairs, the unrelated pairs as one matrix per resolution combination, the
real pairs, and the evidence of each test per group of answers (what calibrates the
thresholds), with a scatter of that evidence.

``verdict.py`` imports this module as a sibling: ``python benchmarks/verdict.py`` puts
``benchmarks/`` on ``sys.path``.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from _verdict_runs import (
    NEAR_ROT_DEG,
    NEAR_TRANS_M,
    SOLVED_ROT_DEG,
    SOLVED_TRANS_M,
    TARGET_CUE,
    TARGET_FALSE_ALARM,
    TARGET_NOT_CONFIDENT,
    summarise,
)

from flexreg.registration.config import RENAMED, RETIRED, JudgeConfig

Record = dict[str, Any]

#: the evidence each test reads, the threshold field and whether passing means above it
TESTS = (
    ("overlap_min", "verdict_min_overlap", True, "smaller overlap (share explained)"),
    ("conflict_max", "verdict_max_conflict", False, "larger free-space conflict"),
    ("axis_min", "verdict_min_axis_strength", True, "weakest axis strength"),
    ("runner_up_ratio", "verdict_ambiguity_ratio", False, "runner-up score ratio"),
    ("spread_ratio", "verdict_min_inlier_spread", True, "inlier spread ratio"),
    ("rmse_ratio", "verdict_max_rmse_ratio", False, "inlier RMSE / threshold"),
)

SHORT = {"confident": "C", "uncertain": "U", "failed": "F"}


def _pct(x: float) -> str:
    return "–" if x is None or math.isnan(x) else f"{100 * x:.0f} %"


def _met(ok: bool) -> str:
    return "**met**" if ok else "**NOT met**"


def _num(x: Any, fmt: str = ".3f") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return format(x, fmt)


def _res(r: Sequence[int]) -> str:
    return f"{r[0]}x{r[1]}"


# ------------------------------------------------------------------ acceptance and counts


def _real_main(real: Sequence[Record]) -> Record | None:
    return next((r for r in real if r["pair"] == "3DTK scan000 <- scan002"), None)


def _real_ok(r: Record | None) -> tuple[bool, str]:
    """Whether the 3DTK pair of the issue meets its goal, and what it did."""
    if r is None:
        return False, "not run (data missing?)"
    if r["status"] == "failed":
        return False, f"failed ({r['error']})"
    what = f"{r['status']}, {r['rot_deg']:.2f}° / {100 * r['trans_m']:.1f} cm from the odometry"
    if r["correct"]:
        return True, what + " (correct)"
    if r["status"] == "uncertain" and r["runner_up_near_truth"]:
        return True, what + ", a runner-up near the odometry"
    return False, what + " (wrong" + (", runner-up not near it)" if r["runner_ups"] else ")")


def acceptance(state: Record) -> list[str]:
    """The acceptance table: each goal of the issue, what was measured and whether it is met."""
    s = state["sets"]
    rows: list[tuple[str, str, str, bool]] = []
    if s.get("ambiguous"):
        a = summarise(s["ambiguous"])
        rows.append(
            (
                "ambiguous pairs not confident (uncertain or failed)",
                f"≥ {TARGET_NOT_CONFIDENT:.0%}",
                f"{a['not_confident']}/{a['pairs']} ({_pct(a['not_confident_rate'])})",
                a["not_confident_rate"] >= TARGET_NOT_CONFIDENT,
            )
        )
    if s.get("cue"):
        kinds = sorted({r["scene"] for r in s["cue"]}, key=[r["scene"] for r in s["cue"]].index)
        per = {k: summarise([r for r in s["cue"] if r["scene"] == k]) for k in kinds}
        rows.append(
            (
                f"cue pairs solved (< {SOLVED_ROT_DEG:g}°, < {100 * SOLVED_TRANS_M:.0f} cm) "
                "and confident, per variant",
                "≥ 5 of 6 each",
                ", ".join(f"{k} {c['solved_confident']}/{c['pairs']}" for k, c in per.items()),
                all(c["solved_confident_rate"] >= TARGET_CUE - 1e-9 for c in per.values()),
            )
        )
    if s.get("normal"):
        n = summarise(s["normal"])
        rows += [
            (
                "normal pairs: every confident answer correct",
                "0 misses",
                f"{n['misses']} wrong of {n['confident']} confident",
                n["misses"] == 0,
            ),
            (
                "normal pairs: correct answers flagged uncertain",
                f"≤ {TARGET_FALSE_ALARM:.0%}",
                f"{n['false_alarms']}/{n['correct']} ({_pct(n['false_alarm_rate'])})",
                not n["false_alarm_rate"] > TARGET_FALSE_ALARM,
            ),
        ]
    if s.get("unrelated"):
        u = summarise(s["unrelated"])
        rows.append(
            (
                "unrelated pairs never confident",
                "0 confident",
                f"{u['confident']}/{u['pairs']} confident",
                u["confident"] == 0,
            )
        )
    if s.get("real"):
        ok, what = _real_ok(_real_main(s["real"]))
        rows.append(("3DTK scan000 ← scan002", "correct, or uncertain + runner-up near", what, ok))
    if s.get("alias"):
        a = summarise(s["alias"])
        rows.append(
            (
                "project alias pairs (identical rooms / bays): every confident answer correct",
                "0 misses",
                f"{a['misses']} wrong of {a['confident']} confident",
                a["misses"] == 0,
            )
        )
    lines = ["| goal | target | measured | |", "|---|---|---|---|"]
    lines += [f"| {g} | {t} | {m} | {_met(ok)} |" for g, t, m, ok in rows]
    return lines


def _count_row(label: str, records: Sequence[Record]) -> str:
    s = summarise(records)
    reasons = ", ".join(f"{k} {v}" for k, v in s["reasons"].items()) or "–"
    return (
        f"| {label} | {s['pairs']} | {s['confident']} | {s['uncertain']} | {s['failed']} | "
        f"{s['correct']} | {s['solved_confident']} | {s['false_alarms']} "
        f"({_pct(s['false_alarm_rate'])}) | {s['misses']} ({_pct(s['miss_rate'])}) | "
        f"{s['symmetric']} | {s['runner_up_near_truth']} | {reasons} |"
    )


def counts(state: Record) -> list[str]:
    """One row per set and per scene kind / resolution within it."""
    lines = [
        "| set | pairs | confident | uncertain | failed | correct | correct and confident | "
        "false alarms (of correct) | misses (of wrong) | at a symmetric pose | wrong, truth "
        "among runner-ups | reasons of the uncertain |",
        "|---|" + "---:|" * 10 + "---|",
    ]
    for name, records in state["sets"].items():
        if not records:
            continue
        lines.append(_count_row(f"**{name}**", records))
        for label, group in _groups(name, records):
            lines.append(_count_row(f"  {label}", group))
    return lines


def _groups(name: str, records: Sequence[Record]) -> list[tuple[str, list[Record]]]:
    """The rows under a set: by scene (and resolution when there are several), by resolution
    combination for unrelated pairs, none for the real pairs."""
    if name in ("real", "alias"):
        return []
    if name == "unrelated":
        key: Callable[[Record], str] = lambda r: (  # noqa: E731
            f"{_res(r['target']['resolution'])} ← {_res(r['source']['resolution'])}"
        )
    elif len({tuple(r["resolution"]) for r in records}) > 1:
        key = lambda r: f"{r['scene']} {_res(r['resolution'])}"  # noqa: E731
    else:
        key = lambda r: r["scene"]  # noqa: E731
    labels = list(dict.fromkeys(key(r) for r in records))
    return [(k, [r for r in records if key(r) == k]) for k in labels]


# ------------------------------------------------------------------ pair tables


def _runner_up_cell(r: Record) -> str:
    if not r.get("runner_ups"):
        return "–"
    u = r["runner_ups"][0]
    cell = f"{u['score_ratio']:.2f} at {u['rot_deg']:.0f}° / {u['trans_m']:.2f} m"
    if "near_truth" in u:
        cell += " (the truth)" if u["near_truth"] else ""
    more = len(r["runner_ups"]) - 1
    return cell + (f" +{more}" if more > 0 else "")


def _pair_row(r: Record, label: str) -> str:
    if r["status"] == "failed":
        return f"| {label} | failed | {r['error_type']}: {r['error'][:70]} |" + " |" * 7
    e = r["evidence"]
    err = f"{r['rot_deg']:.2f}° / {r['trans_m']:.3f} m" if "rot_deg" in r else "–"
    axis = f"{_num(e.get('axis_min'))} ({e.get('axis_min_name') or '–'})"
    sc = r.get("scored", {})
    scores = " / ".join(
        _num(sc.get(k, {}).get("score"), ".3f") for k in ("answer", "runner_up", "truth")
    )
    conflicts = " / ".join(
        _num(max(sc[k]["conflicting"]) * 100, ".1f") if k in sc else "–"
        for k in ("answer", "runner_up", "truth")
    )
    return (
        f"| {label} | {r['status']} | {', '.join(r['reasons']) or '–'} | {err} | "
        f"{r.get('pose', '–')} | {_runner_up_cell(r)} | {_num(e.get('overlap_min'), '.2f')} | "
        f"{axis} | {scores} | {conflicts} |"
    )


PAIR_HEADER = [
    "| pair | verdict | reasons | error | answer | best runner-up: score ratio, distance | "
    "overlap (min) | weakest axis | two-way score: answer / runner-up / truth | free-space "
    "conflict % (larger direction): answer / runner-up / truth |",
    "|---|---|---|---|---|---|---:|---|---|---|",
]


def pair_table(records: Sequence[Record], only_notable: bool = False) -> list[str]:
    """One row per synthetic pair (with ``only_notable``: the uncertain, failed or wrong ones)."""
    rows = [
        _pair_row(r, f"{r['scene']} {r['seed']}" + (f" {_res(r['resolution'])}"))
        for r in records
        if not only_notable or r["status"] != "confident" or not r.get("correct")
    ]
    return PAIR_HEADER + rows if rows else ["(none)"]


def real_table(records: Sequence[Record]) -> list[str]:
    """The real pairs: verdict, error to the reference, runner-ups and their distance to it."""
    lines = [
        "| pair | reference (correct within) | verdict | reasons | error | runner-ups: score "
        "ratio, distance to the answer → to the reference |",
        "|---|---|---|---|---|---|",
    ]
    for r in records:
        lim = f"{r['reference']} ({r['solved'][0]:g}°, {100 * r['solved'][1]:g} cm)"
        if r["status"] == "failed":
            lines.append(f"| {r['pair']} | {lim} | failed | {r['error']} | – | – |")
            continue
        ups = "; ".join(
            f"{u['score_ratio']:.2f}: {u['rot_deg']:.1f}° / {u['trans_m']:.2f} m → "
            f"{u['truth_rot_deg']:.1f}° / {u['truth_trans_m']:.2f} m"
            for u in r["runner_ups"]
        )
        lines.append(
            f"| {r['pair']} | {lim} | {r['status']} | {', '.join(r['reasons']) or '–'} | "
            f"{r['rot_deg']:.2f}° / {100 * r['trans_m']:.1f} cm | {ups or '–'} |"
        )
    return lines


def alias_table(records: Sequence[Record]) -> list[str]:
    """The project alias pairs: true overlap, verdict, reasons, error, runner-ups."""
    lines = [
        "| pair | true overlap | verdict | reasons | error | best runner-up |",
        "|---|---:|---|---|---|---|",
    ]
    for r in records:
        head = f"| {r['pair']} | {r['true_overlap']:.3f} |"
        if r["status"] == "failed":
            lines.append(f"{head} failed | {r['error']} | – | – |")
            continue
        lines.append(
            f"{head} {r['status']} | {', '.join(r['reasons']) or '–'} | "
            f"{r['rot_deg']:.2f}° / {r['trans_m']:.3f} m | {_runner_up_cell(r)} |"
        )
    return lines


def unrelated_matrices(records: Sequence[Record]) -> list[str]:
    """One kind x kind matrix per resolution combination: C confident, U uncertain (with its
    reasons' initials), F failed."""
    lines: list[str] = []
    for label, group in _groups("unrelated", records):
        kinds = list(dict.fromkeys(r["target"]["scene"] for r in group))
        cell = {(r["target"]["scene"], r["source"]["scene"]): r for r in group}
        lines += [
            f"Target {label.split(' ← ')[0]}, source {label.split(' ← ')[1]}:",
            "",
            "| target \\ source | " + " | ".join(kinds) + " |",
            "|---|" + "---|" * len(kinds),
        ]
        for a in kinds:
            row = [_unrelated_cell(cell.get((a, b))) for b in kinds]
            lines.append(f"| {a} | " + " | ".join(row) + " |")
        lines.append("")
    return lines


def _unrelated_cell(r: Record | None) -> str:
    if r is None:
        return ""
    s = SHORT.get(r["status"], r["status"])
    if r["status"] == "uncertain":
        s += " " + "+".join(sorted({c.split("_")[-1] for c in r["reasons"]}))
    return f"**{s}**" if r["status"] == "confident" else s


# ------------------------------------------------------------------ evidence per group


def evidence_groups(state: Record) -> list[tuple[str, list[Record]]]:
    """Answers grouped by what their verdict should be: correct ones (should be confident) and
    wrong or unanswerable ones (should be uncertain)."""
    s = state["sets"]

    def answered(name: str) -> list[Record]:
        return [r for r in s.get(name, []) if r["status"] != "failed"]

    out = [
        ("normal, correct", [r for r in answered("normal") if r["correct"]]),
        ("cue, correct", [r for r in answered("cue") if r["correct"]]),
        ("real, correct", [r for r in answered("real") if r["correct"]]),
        ("ambiguous, correct", [r for r in answered("ambiguous") if r["correct"]]),
        ("ambiguous, wrong", [r for r in answered("ambiguous") if not r["correct"]]),
        ("cue, wrong", [r for r in answered("cue") if not r["correct"]]),
        ("normal, wrong", [r for r in answered("normal") if not r["correct"]]),
        ("real, wrong", [r for r in answered("real") if not r["correct"]]),
        ("unrelated", answered("unrelated")),
    ]
    return [(k, v) for k, v in out if v]


def _spread(values: list[float]) -> str:
    if not values:
        return "–"
    return f"{min(values):.3f} / {statistics.median(values):.3f} / {max(values):.3f}"


def evidence_table(state: Record) -> list[str]:
    """Min / median / max of each test's evidence per group, and the threshold."""
    cfg = state["config"]
    groups = evidence_groups(state)
    lines = [
        "| evidence (test passes when) | "
        + " | ".join(f"{k} ({len(v)})" for k, v in groups)
        + " |",
        "|---|" + "---|" * len(groups),
    ]
    for key, field, above, label in TESTS:
        t = threshold(cfg, field)
        cond = f"{label} {'≥' if above else '≤' if key != 'runner_up_ratio' else '<'} {t}"
        cells = [
            _spread([r["evidence"][key] for r in v if r["evidence"].get(key) is not None])
            for _, v in groups
        ]
        lines.append(f"| {cond} | " + " | ".join(cells) + " |")
    for label, fn in DERIVED:
        cells = [_spread([x for x in (fn(r) for r in v) if x is not None]) for _, v in groups]
        lines.append(f"| {label} (no test) | " + " | ".join(cells) + " |")
    return lines


def _sc(r: Record, key: str) -> dict[str, Any] | None:
    return r.get("scored", {}).get(key)


def _soft_ratio(r: Record) -> float | None:
    a, u = _sc(r, "answer"), _sc(r, "runner_up")
    return u["score"] / a["score"] if a and u and a["score"] > 1e-9 else None


def _conflict_excess(r: Record) -> float | None:
    a, u = _sc(r, "answer"), _sc(r, "runner_up")
    return max(u["conflicting"]) - max(a["conflicting"]) if a and u else None


def _truth_gain(r: Record) -> float | None:
    a, t = _sc(r, "answer"), _sc(r, "truth")
    return t["score"] - a["score"] if a and t else None


#: evidence no test reads yet, candidates for separating the cases
DERIVED: tuple[tuple[str, Callable[[Record], float | None]], ...] = (
    ("the answer's two-way soft score", lambda r: (_sc(r, "answer") or {}).get("score")),
    ("runner-up's two-way soft score / the answer's", _soft_ratio),
    ("runner-up's free-space conflict − the answer's (larger direction)", _conflict_excess),
    ("truth's two-way soft score − the answer's", _truth_gain),
)


# ------------------------------------------------------------------ the figure


def plot_evidence(state: Record, path: Path) -> None:
    """Two panels of every answer: runner-up score ratio vs the smaller overlap, and the
    weakest axis strength vs the larger free-space conflict, with the thresholds; colour by
    group, filled = confident, cross = uncertain."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg = state["config"]
    colours = ["#009E73", "#56B4E9", "#E69F00", "#999999", "#D55E00", "#CC79A7", "#F0E442"]
    colours += ["#000000", "#0072B2"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), dpi=110)
    panels = (
        ("runner_up_ratio", "overlap_min", "runner-up score ratio", "smaller overlap"),
        ("conflict_max", "axis_min", "larger free-space conflict", "weakest axis strength"),
    )
    for ax, (kx, ky, lx, ly) in zip(axes, panels, strict=True):
        for (label, rs), c in zip(evidence_groups(state), colours, strict=False):
            for status, marker in (("confident", "o"), ("uncertain", "x")):
                pts = [
                    (r["evidence"].get(kx), r["evidence"].get(ky))
                    for r in rs
                    if r["status"] == status
                ]
                floor = 1e-4 if ky == "axis_min" else -math.inf  # log axis: zero on its floor
                pts = [
                    (x if x is not None else 0.0, max(y, floor)) for x, y in pts if y is not None
                ]
                if pts:
                    xs, ys = zip(*pts, strict=True)
                    ax.scatter(
                        xs, ys, marker=marker, color=c, s=22, label=f"{label}: {status}", alpha=0.8
                    )
        ax.set_xlabel(lx + (" (none = 0)" if kx == "runner_up_ratio" else ""))
        ax.set_ylabel(ly)
    axes[0].axvline(threshold(cfg, "verdict_ambiguity_ratio"), color="0.3", ls="--", lw=0.8)
    axes[0].axhline(threshold(cfg, "verdict_min_overlap"), color="0.3", ls="--", lw=0.8)
    axes[1].axvline(threshold(cfg, "verdict_max_conflict"), color="0.3", ls="--", lw=0.8)
    axes[1].axhline(threshold(cfg, "verdict_min_axis_strength"), color="0.3", ls="--", lw=0.8)
    axes[1].set_yscale("log")
    axes[1].legend(fontsize=6, loc="best", ncol=2)
    fig.suptitle("Verdict evidence (dashed: thresholds; uncertain left of / below them)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ------------------------------------------------------------------ the page


def _intro(state: Record) -> list[str]:
    m = state["machine"]
    total = state.get("total_s")
    return [
        "Whether `register`'s verdict (`confident` / `uncertain`, or a failure that writes "
        "nothing) can be trusted: the acceptance of issue 17, measured. An answer is **correct** "
        f"within {SOLVED_ROT_DEG:g}° and {100 * SOLVED_TRANS_M:.0f} cm of the truth (real pairs: "
        "the limits in their table). **False alarm**: correct but uncertain; **miss**: wrong but "
        "confident (every answer to an unrelated pair is wrong; on the ambiguous set every answer "
        "should be uncertain, so its false alarms are no fault). A runner-up is *near the truth* "
        f"within {NEAR_ROT_DEG:g}° and {100 * NEAR_TRANS_M:.0f} cm. One registration per pair "
        "with the default configuration (ICP refinement on, seed 0), run as "
        "`Registration.prepare` of both scans and `align` (bit for bit `register`'s result) so "
        "that the pair's dense check can also score the truth and the runner-up.",
        "",
        f"Command: `{state['command']}` — {_num(total / 60 if total else None, '.1f')} min on "
        f"{m.get('cores', '?')} cores ({m.get('cpu', '?')}); load "
        f"average at the start {state['load_average']['start'][0]:.1f} (the machine is shared). "
        "Raw records: `benchmarks/results/verdict-<timestamp>/results.json`; "
        "`--from-json` renders a saved run again.",
        "",
    ]


def threshold(cfg: Record, key: str) -> float:
    """A verdict threshold of a run's configuration by its flat name (``verdict_min_overlap``),
    in either layout: the flat one of older runs, or the ``judge`` table (a threshold that is
    a module constant now is read from :mod:`flexreg.registration.config`)."""
    if key in cfg:
        return float(cfg[key])
    judge = JudgeConfig(**cfg.get("judge", {}))
    if key in RENAMED:
        return float(getattr(judge, RENAMED[key].partition(".")[2]))
    return float(RETIRED[key][0])


def _thresholds(state: Record) -> list[str]:
    cfg = state["config"]
    flat = {k: v for k, v in cfg.items() if k.startswith("verdict_")}
    table = flat or {f"judge.{k}": v for k, v in cfg.get("judge", {}).items() if k != "checks"}
    return [
        "Thresholds (`RegistrationConfig`, the defaults at the time of the run):",
        "",
        "| " + " | ".join(f"`{k}`" for k in table) + " |",
        "|" + "---:|" * len(table),
        "| " + " | ".join(str(v) for v in table.values()) + " |",
        "",
    ]


def _sets_text(state: Record) -> list[str]:
    p = state["plan"]
    return [
        "Sets (stations from `flexreg.synth.station_pair`: 2–10 m apart, mutual overlap ≥ 0.5, "
        "tilt ≤ 5°, 3 mm range noise):",
        "",
        f"* **ambiguous**: {', '.join(p['ambiguous_kinds'])}, seeds {p['seeds']}, "
        f"{_res(p['resolution'])};",
        f"* **cue**: {', '.join(p['cue_kinds'])}, seeds {p['seeds']}, {_res(p['resolution'])};",
        f"* **normal**: {', '.join(p['normal_kinds'])}, seeds {p['normal_seeds']} at "
        + " and ".join(
            f"{_res(r)}" + (f" (seeds {s})" if s != p["normal_seeds"] else "")
            for r, s in p["normal_resolutions"]
        )
        + ";",
        f"* **unrelated**: a station of {', '.join(p['unrelated_kinds'])} (seed 0) against "
        "one of every later kind (seed 0) and of the same kind with seed 1 (another scene; also "
        "seed 1 for a kind against its cue variant, which is the same scene but for the cue), "
        "at target ← source resolutions "
        + ", ".join(f"{_res(a)} ← {_res(b)}" for a, b in p["unrelated_resolutions"])
        + ";",
        "* **real**: " + ", ".join(r["pair"] for r in state["sets"].get("real", [])) + ";",
        "* **alias**: " + ", ".join(r["pair"] for r in state["sets"].get("alias", [])) + ".",
        "",
    ]


def markdown(state: Record, figure: str | None) -> str:
    """The ``## Verdict`` section of docs/benchmarks.md (without its heading)."""
    s = state["sets"]
    lines = _intro(state) + _thresholds(state) + _sets_text(state)
    lines += ["### Acceptance", ""] + acceptance(state) + [""]
    lines += ["### Counts per set", ""] + counts(state) + [""]
    for name, title in (("ambiguous", "Ambiguous pairs"), ("cue", "One-cue variants")):
        if s.get(name):
            lines += [f"### {title}", ""] + pair_table(s[name]) + [""]
    if s.get("normal"):
        lines += [
            "### Normal pairs that were not confident and correct",
            "",
            *pair_table(s["normal"], only_notable=True),
            "",
        ]
    if s.get("unrelated"):
        lines += [
            "### Unrelated pairs",
            "",
            "C confident (**a miss**), U uncertain with its reasons (overlap = low_overlap, "
            "space = free_space, axis = weak_axis, ambiguous, inliers = few/clustered, residual "
            "= high_residual), F failed (nothing written).",
            "",
            *unrelated_matrices(s["unrelated"]),
        ]
    if s.get("real"):
        lines += ["### Real pairs", "", *real_table(s["real"]), ""]
    if s.get("alias"):
        lines += [
            "### Project alias pairs",
            "",
            "Pairs of `flexreg synth --scene building|warehouse --stations 10 --resolution "
            "1024x512 --seed 0` that a survey once linked confidently and wrongly (the true "
            "pose barely overlaps: a wrong pose overlays two identical rooms or bays), and two "
            "pairs that do overlap. True overlap: the smaller share of either station the "
            "other sees (gt.json).",
            "",
            *alias_table(s["alias"]),
            "",
        ]
    lines += [
        "### Evidence per group (min / median / max)",
        "",
        "What each test reads, for the answers that should pass (correct) and those that should "
        "not (wrong, unrelated); a threshold separates the groups where their ranges do not "
        "overlap. The last rows are read by no test: the verdict's two-way soft score "
        "(`TwoWay.score` at half the inlier threshold, the refinement guard's score) of the "
        "best runner-up and of the true pose against the answer's, from the same dense check. "
        "A positive truth − answer difference on a wrong answer means the check prefers the "
        "truth and the candidates missed it; a negative one, that the check itself prefers the "
        "wrong pose.",
        "",
        *evidence_table(state),
        "",
    ]
    if figure:
        lines += [f"![verdict evidence]({figure})", ""]
    return "\n".join(lines)
