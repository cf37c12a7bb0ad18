"""The survey report: one self-contained HTML page a surveyor reads after ``flexreg survey``.

:func:`render_report` turns a poses document (the content of ``DIR/poses.json``) into the page;
:func:`write_report` writes it atomically. The page needs nothing but a browser: no network, no
other file. The station graph is inline SVG drawn with matplotlib; the style sheet and the few
lines of script that sort the tables are inline too.

What the page shows, top to bottom:

* the outcome in one line, the way the command's exit code says it (done and confident,
  done but uncertain, failed) and the figures of the whole project: stations placed, links
  attempted / accepted / rejected / failed, bundle error, mean and max link error;
* what needs the operator: the unplaced stations and why, the kept links that are uncertain;
* the station graph: a plan view of each group of stations with its links coloured by status
  (rejected links labelled with their loop error);
* the table of links: overlap, inliers, cloud-to-cloud RMSE, strength per axis, loop error,
  link error after the adjustment, verdict and reasons, status;
* the stations: placed, group, position, links, max link error;
* the groups, and how every figure is defined.

The *link error* of an accepted link is how far the link's own ``T_target_source`` disagrees
with the adjusted poses: the engine's ``loop_error_deg`` / ``loop_error_m`` of that link, or,
for a document without them, the rotation angle and the displacement of the source's origin
between the link and ``inv(T_group_target) @ T_group_source``. The *bundle error* is the root
mean square of the accepted links' errors (the document's summary when it gives one). The
figures are in :mod:`flexreg.survey.report_data`.
"""

from __future__ import annotations

import html
import io
import logging
import math
from collections.abc import Mapping, Sequence
from numbers import Real
from pathlib import Path
from typing import Any

import numpy as np

from flexreg.errors import InputError
from flexreg.io.files import atomic_write
from flexreg.survey.report_data import (
    AXES,
    LinkError,
    ReportFigures,
    check_document,
    group_of,
    link_errors,
    link_inliers,
    link_kind,
    link_overlap,
    link_pose_source,
    link_reasons,
    link_rmse,
    link_strength,
    report_figures,
    station_pose,
    station_reasons,
    weak_axis_threshold,
)

log = logging.getLogger(__name__)

__all__ = ["drawn_groups", "render_report", "station_graph_svg", "write_report"]

#: link colours by kind (Okabe-Ito: distinguishable when colour-blind)
COLOURS = {
    "confident": "#009E73",
    "uncertain": "#E69F00",
    "rejected": "#D55E00",
    "failed": "#7F7F7F",
}
STATION_COLOUR, FRAME_COLOUR = "#0072B2", "#CC79A7"
STYLES = {"confident": "-", "uncertain": "-", "rejected": "--", "failed": ":"}
WIDTHS = {"confident": 1.6, "uncertain": 2.4, "rejected": 1.4, "failed": 1.0}
KIND_WORDS = {
    "confident": "accepted, confident",
    "uncertain": "accepted, uncertain",
    "rejected": "rejected",
    "failed": "failed",
}


# --------------------------------------------------------------------------- station graph


def _plain(text: str) -> str:
    """``text`` for matplotlib as it is (a ``$`` in a station's name is not mathematics)."""
    return text.replace("$", r"\$")


def _xy(doc: Mapping[str, Any], stems: Sequence[str]) -> dict[str, np.ndarray]:
    """Plan positions (x, y in metres, the group's frame) of ``stems`` that have a pose."""
    out = {}
    for s in stems:
        T = station_pose(doc["stations"][s])
        if T is not None:
            out[s] = T[:2, 3]
    return out


def _links_between(
    doc: Mapping[str, Any], pos: Mapping[str, np.ndarray]
) -> tuple[dict[str, list[Any]], list[tuple[np.ndarray, str]]]:
    """Segments per link kind among stations of ``pos``, and the labels of rejected links
    (midpoint, loop error)."""
    segs: dict[str, list[Any]] = {k: [] for k in COLOURS}
    labels = []
    for lk in doc["links"]:
        a, b = pos.get(lk["target"]), pos.get(lk["source"])
        if a is None or b is None:
            continue
        kind = link_kind(lk)
        segs[kind].append([a, b])
        d, m = lk.get("loop_error_deg"), lk.get("loop_error_m")
        if kind == "rejected" and d is not None:
            labels.append(((a + b) / 2, f"{d:.1f}°" + ("" if m is None else f" / {m:.2f} m")))
    return segs, labels


def _draw_group(ax: Any, doc: Mapping[str, Any], stems: list[str], frame: str) -> dict[str, int]:
    """Draw one group's stations and links on ``ax``; return how many links of each kind it
    drew."""
    from matplotlib.collections import LineCollection

    pos = _xy(doc, stems)
    segs, labels = _links_between(doc, pos)
    for kind in ("failed", "confident", "uncertain", "rejected"):
        if segs[kind]:
            ax.add_collection(
                LineCollection(
                    segs[kind],
                    colors=COLOURS[kind],
                    linestyles=STYLES[kind],
                    linewidths=WIDTHS[kind],
                    zorder=3 if kind == "rejected" else 2,
                )
            )
    for mid, text in labels:
        ax.annotate(
            text,
            mid,
            fontsize=7,
            color=COLOURS["rejected"],
            ha="center",
            zorder=6,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
        )
    xy = np.array(list(pos.values())).reshape(-1, 2)
    ax.scatter(xy[:, 0], xy[:, 1], s=24, c=STATION_COLOUR, zorder=4)
    if frame in pos:
        ax.scatter(*pos[frame], s=160, marker="*", c=FRAME_COLOUR, zorder=5)
    for s, p in pos.items():
        ax.annotate(_plain(s), p, xytext=(3, 3), textcoords="offset points", fontsize=7, zorder=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.margins(0.08)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    return {k: len(v) for k, v in segs.items()}


def _legend(fig: Any, drawn: Mapping[str, int]) -> None:
    """One legend under all panels: the kinds of link drawn (with their counts), stations and
    the frame origin."""
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color=COLOURS[k], ls=STYLES[k], lw=WIDTHS[k], label=f"{KIND_WORDS[k]} ({n})")
        for k, n in drawn.items()
        if n
    ]
    handles += [
        Line2D([], [], ls="", marker="o", color=STATION_COLOUR, label="station"),
        Line2D([], [], ls="", marker="*", ms=12, color=FRAME_COLOUR, label="frame origin"),
    ]
    fig.legend(
        handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8, frameon=False
    )


def drawn_groups(doc: Mapping[str, Any], f: ReportFigures) -> dict[int, list[str]]:
    """The groups the station graph draws: the reference's and every group with at least two
    stations that have a pose (a station alone in its group is listed, not drawn)."""
    reference = str(doc.get("reference", ""))
    return {
        g: stems
        for g, stems in f.groups.items()
        if len(_xy(doc, stems)) >= 2 or (reference in stems and _xy(doc, stems))
    }


def _layout(
    doc: Mapping[str, Any], groups: Mapping[int, list[str]]
) -> tuple[tuple[float, float], list[float]]:
    """Figure size (inches) and column width ratios: up to three groups side by side, each
    panel as wide as its stations' plan extent needs at a common height; more groups in rows
    of three equal panels."""
    n = len(groups)
    if n > 3:
        return (13.0, 4.8 * math.ceil(n / 3)), [1.0, 1.0, 1.0]
    ratios = []
    for stems in groups.values():
        xy = np.array(list(_xy(doc, stems).values())).reshape(-1, 2)
        dx, dy = (np.ptp(xy, axis=0) + 4.0) if len(xy) else (4.0, 4.0)
        ratios.append(float(np.clip(dx / dy, 0.6, 4.0)))
    ratios = ratios or [1.0]
    width = 10.0 if n <= 1 else 13.0
    extra_w, extra_h = 0.9 * len(ratios), 1.6  # axis labels; titles and the legend
    height = (width - extra_w) / sum(ratios) + extra_h
    if height > 9.0:  # a tall project: narrower, not taller
        height = 9.0
        width = max((height - extra_h) * sum(ratios) + extra_w, 7.0)
    return (width, max(height, 3.8)), ratios


def station_graph_svg(doc: Mapping[str, Any], figures: ReportFigures | None = None) -> str:
    """The station graph as an inline ``<svg>`` element.

    A plan view (x, y in metres) of each group's stations in the group's frame, one panel per
    group; links coloured by kind (accepted and confident, accepted and uncertain, rejected --
    dashed, labelled with the loop error --, failed -- dotted); the station whose frame the
    group is in starred. Drawn with matplotlib's object interface (no pyplot, no global
    state); text stays text, so the page can be searched.

    Parameters
    ----------
    doc : dict
        A poses document.
    figures : ReportFigures, optional
        From :func:`~flexreg.survey.report_data.report_figures` (computed when not given).
    """
    import matplotlib  # heavy: only when a report is drawn
    from matplotlib.figure import Figure

    f = report_figures(doc) if figures is None else figures
    shown = drawn_groups(doc, f)
    size, ratios = _layout(doc, shown)
    fig = Figure(figsize=size, dpi=96, layout="constrained")
    cols = len(ratios)
    grid = fig.add_gridspec(max(1, math.ceil(len(shown) / cols)), cols, width_ratios=ratios)
    reference = str(doc.get("reference", ""))
    if not shown:
        ax = fig.add_subplot(grid[0, 0])
        ax.text(0.5, 0.5, "no station placed", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
    drawn = dict.fromkeys(COLOURS, 0)
    for i, (g, stems) in enumerate(shown.items()):
        ax = fig.add_subplot(grid[i // cols, i % cols])
        frame = f.group_frames.get(g, "")
        counts = _draw_group(ax, doc, stems, frame)
        drawn = {k: drawn[k] + counts[k] for k in drawn}
        where = "reference frame" if frame == reference else "own frame, not joined"
        ax.set_title(
            f"group {g}: {_plural(len(stems), 'station')}, "
            f"{_plural(sum(counts.values()), 'link')}\n({where}: {_plain(frame)})",
            fontsize=9,
        )
    _legend(fig, drawn)
    buf = io.StringIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "flexreg-survey"}):
        fig.savefig(buf, format="svg", metadata={"Date": None})
    svg = buf.getvalue()
    return svg[svg.index("<svg") :]


# --------------------------------------------------------------------------- HTML pieces


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _num(x: Any, fmt: str, unit: str = "") -> str:
    """A number as text (``–`` when missing, not a number or not finite)."""
    if not isinstance(x, Real) or isinstance(x, bool) or not math.isfinite(x):
        return "–"
    return format(float(x), fmt) + unit


def _cell(text: str, sort: float | str | None = None, cls: str = "") -> str:
    """A table cell; ``sort`` is the value its column sorts by (the text when not given)."""
    attrs = f' class="{cls}"' if cls else ""
    if sort is not None and not (isinstance(sort, float) and not math.isfinite(sort)):
        attrs += f' data-sort="{_e(sort)}"'
    return f"<td{attrs}>{_e(text)}</td>"


def _table(tid: str, headers: Sequence[tuple[str, str]], rows: Sequence[str]) -> str:
    """A sortable table; ``headers`` are (label, tooltip)."""
    head = "".join(f'<th title="{_e(tip)}">{_e(h)}</th>' for h, tip in headers)
    body = "\n".join(rows) or f'<tr class="empty"><td colspan="{len(headers)}">none</td></tr>'
    return (
        f'<div class="scroll"><table id="{_e(tid)}" class="sortable"><thead><tr>{head}</tr>'
        f"</thead><tbody>\n{body}\n</tbody></table></div>"
    )


def _pct(x: float | None) -> str:
    return _num(None if x is None else 100 * x, ".0f")


def _mm(x: float | None) -> str:
    return _num(None if x is None else 1000 * x, ".1f")


LINK_HEADERS = (
    ("#", "link number, in the order of poses.json"),
    ("target", "the station the link maps into"),
    ("source", "the station the link maps from"),
    ("status", "accepted into the adjustment, rejected (loop check) or failed"),
    ("verdict", "the pairwise registration's verdict"),
    ("tried as", "why the pair was tried: sequential, place recognition, proximity, all, file"),
    ("overlap src %", "share of the source's points that the target explains"),
    ("overlap tgt %", "share of the target's points that the source explains"),
    (
        "inliers",
        "feature matches that agree with the link / matches tested ('pose from the plan view': "
        "the plan views' overlay found the pose, not feature matches)",
    ),
    ("RMSE mm", "cloud-to-cloud RMSE of the link's inliers, millimetres"),
    *((f"str. {a}", f"strength along / about {a}: 0 not constrained, 1 fully") for a in AXES),
    ("loop err °", "accepted: disagreement with the adjusted poses; rejected: with its loop"),
    ("loop err mm", "accepted: disagreement with the adjusted poses; rejected: with its loop"),
    ("reasons", "why the link is rejected, failed or uncertain"),
)


def _link_row(i: int, lk: Mapping[str, Any], err: LinkError | None, weak: float) -> str:
    kind = link_kind(lk)
    s_ov, t_ov = link_overlap(lk)
    n, m = link_inliers(lk)
    source = link_pose_source(lk)  # not fitted to matches: the counts measure nothing
    strength = link_strength(lk)
    rmse = link_rmse(lk)
    d = err.rotation_deg if err else lk.get("loop_error_deg")
    t = err.translation_m if err else lk.get("loop_error_m")
    unchecked = lk.get("loop_error") == "unchecked"  # closes no loop: no error to show
    verdict = lk.get("verdict")
    v = verdict.get("status") if isinstance(verdict, Mapping) else verdict
    cells = [
        _cell(str(i), i),
        _cell(lk["target"]),
        _cell(lk["source"]),
        _cell(str(lk.get("status", "failed")), cls=f"k-{kind}"),
        _cell("–" if v is None else str(v)),
        _cell(str(lk.get("origin") or "–")),
        _cell(_pct(s_ov), s_ov),
        _cell(_pct(t_ov), t_ov),
        _cell(source or ("–" if n is None else (f"{n}" if m is None else f"{n} / {m}")), n),
        _cell(_mm(rmse), rmse),
    ]
    for a in AXES:
        x = strength.get(a)
        cells.append(_cell(_num(x, ".3f"), x, "weak" if x is not None and x < weak else ""))
    cells += [
        _cell("unchecked" if unchecked else _num(d, ".3f"), None if unchecked else d),
        _cell("unchecked" if unchecked else _mm(t), None if unchecked else t),
        _cell("; ".join(link_reasons(lk)), cls="text"),
    ]
    return f'<tr class="link {kind}">' + "".join(cells) + "</tr>"


STATION_HEADERS = (
    ("station", "file name without extension"),
    ("placed", "whether the station has a pose in the reference frame"),
    ("group", "connected group of stations (each group in its own frame)"),
    (
        "status",
        "verified: within the tolerance and confirmed by an independent route; placed: within "
        "it, one pair alone places it; outside tolerance: its error may exceed it; unplaced",
    ),
    ("x m", "position in the group's frame"),
    ("y m", "position in the group's frame"),
    ("z m", "position in the group's frame"),
    ("points", "valid returns of the scan"),
    ("links", "accepted / attempted links of the station"),
    ("max err °", "largest rotation error of its accepted links"),
    ("max err mm", "largest displacement error of its accepted links"),
    ("file", "the scan file"),
    ("notes", "why it is unplaced or unreadable"),
)


def _station_row(
    stem: str, st: Mapping[str, Any], mine: Sequence[tuple[Mapping[str, Any], LinkError | None]]
) -> str:
    T = station_pose(st)
    p = None if T is None else T[:3, 3]
    acc = sum(lk.get("status") == "accepted" for lk, _ in mine)
    es = [e for _, e in mine if e is not None]
    dmax = max((e.rotation_deg for e in es), default=None)
    mmax = max((e.translation_m for e in es), default=None)
    placed = bool(st.get("placed"))
    g = group_of(st)
    conf = st.get("status") or st.get("confidence")  # older documents: the confidence
    cells = [
        _cell(stem),
        _cell("yes" if placed else "NO", int(placed), "" if placed else "k-rejected"),
        _cell("–" if g is None else str(g), g),
        _cell(
            "–" if conf is None else str(conf).replace("_", " "), cls=f"k-{conf}" if conf else ""
        ),
        *(
            _cell(_num(None if p is None else p[k], ".3f"), None if p is None else p[k])
            for k in range(3)
        ),
        _cell(_num(st.get("points"), ",.0f"), st.get("points")),
        _cell(f"{acc} / {len(mine)}", acc),
        _cell(_num(dmax, ".3f"), dmax),
        _cell(_mm(mmax), mmax),
        _cell(str(st.get("file") or "–"), cls="text"),
        _cell("; ".join(station_reasons(st)), cls="text"),
    ]
    cls = "station" if placed else "station unplaced"
    return f'<tr class="{cls}">' + "".join(cells) + "</tr>"


def _station_rows(doc: Mapping[str, Any], errs: Sequence[LinkError | None]) -> list[str]:
    per: dict[str, list[tuple[Mapping[str, Any], LinkError | None]]] = {
        s: [] for s in doc["stations"]
    }
    for lk, e in zip(doc["links"], errs, strict=True):
        per[lk["target"]].append((lk, e))
        if lk["source"] != lk["target"]:
            per[lk["source"]].append((lk, e))
    return [_station_row(stem, st, per[stem]) for stem, st in doc["stations"].items()]


def _kpi(label: str, value: str, tip: str = "") -> str:
    return (
        f'<div class="kpi" title="{_e(tip)}"><div class="v">{_e(value)}</div>'
        f'<div class="l">{_e(label)}</div></div>'
    )


def _err_pair(deg: float | None, m: float | None) -> str:
    if deg is None or m is None:
        return "–"
    return f"{deg:.3f}° / {1000 * m:.1f} mm"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'s' * (n != 1)}"


def _outcome_line(f: ReportFigures) -> str:
    if f.outcome == "failed":
        return "Failed: no station could be registered to another (exit 1)."
    if f.outcome == "confident":
        return "Done: every station is verified within the tolerance (exit 0)."
    parts = [f.status_line] if f.status_line else []
    if f.unplaced and not f.status_line:
        parts.append(_plural(len(f.unplaced), "station") + " not placed")
    if f.uncertain_links:
        parts.append(_plural(len(f.uncertain_links), "kept link") + " uncertain")
    if len(f.groups) > 1:
        parts.append(f"{len(f.groups)} groups that no link joins")
    return "Done, but check (exit 3): " + (", ".join(parts) or "see the problems below") + "."


def _summary_section(doc: Mapping[str, Any], f: ReportFigures) -> str:
    L = f.links
    kpis = [
        _kpi("stations placed", f"{f.placed} / {f.stations}", "placed in the reference frame"),
        _kpi("groups", str(len(f.groups)), "connected groups of stations"),
        _kpi("reference", str(doc.get("reference", "–")), "the frame of the poses"),
        _kpi("links attempted", str(sum(L.values()))),
        _kpi("accepted", str(L["confident"] + L["uncertain"]), "kept in the adjustment"),
        _kpi("uncertain kept", str(L["uncertain"]), "accepted links whose verdict is uncertain"),
        _kpi("rejected", str(L["rejected"]), "refused by the loop check"),
        _kpi("failed", str(L["failed"]), "the pair could not be registered"),
        _kpi(
            "bundle error",
            _err_pair(f.bundle_error_deg, f.bundle_error_m),
            "root mean square of the accepted links' errors against the adjusted poses",
        ),
        _kpi("mean link error", _err_pair(f.mean_link_error_deg, f.mean_link_error_m)),
        _kpi("max link error", _err_pair(f.max_link_error_deg, f.max_link_error_m)),
    ]
    return (
        f'<section id="summary"><p class="outcome {f.outcome}">{_e(_outcome_line(f))}</p>'
        f'<div class="kpis">{"".join(kpis)}</div></section>'
    )


def _arrow(lk: Mapping[str, Any]) -> str:
    return f"<b>{_e(lk['target'])} ← {_e(lk['source'])}</b>"


def _attention_section(doc: Mapping[str, Any], f: ReportFigures) -> str:
    st, links = doc["stations"], doc["links"]
    unplaced = [
        f"<li><b>{_e(s)}</b>: {_e('; '.join(station_reasons(st[s])) or 'no link placed it')}</li>"
        for s in f.unplaced
    ]
    loop = {True: " (a closed loop confirms it)", False: " (no closed loop confirms it)"}
    uncertain = [
        f"<li>link {i}: {_arrow(links[i])}: "
        f"{_e('; '.join(link_reasons(links[i])) or 'uncertain')}"
        f"{loop.get(links[i].get('confirmed_by_loop'), '')}</li>"
        for i in f.uncertain_links
    ]
    rejected = [
        f"<li>link {i}: {_arrow(lk)} (loop error "
        f"{_e(_num(lk.get('loop_error_deg'), '.2f', '°'))} / "
        f"{_e(_num(lk.get('loop_error_m'), '.3f', ' m'))}): "
        f"{_e('; '.join(link_reasons(lk)) or 'rejected')}</li>"
        for i, lk in enumerate(links)
        if link_kind(lk) == "rejected"
    ]
    mc = doc.get("map_check") or {}
    conflicts = [
        f"<li>{_e(c['a'])} and {_e(c['b'])}: {_e(c['why'])}</li>"
        for c in mc.get("conflicts_found", [])
    ] + [
        f"<li><b>still contradicting</b>: {_e(c['a'])} and {_e(c['b'])} "
        f"({100 * max(c['conflicting']):.1f}% of one station's points in the other's free "
        "space)</li>"
        for c in mc.get("conflicting_now", [])
    ]
    out = ['<section id="attention"><h2>What needs a look</h2>']
    for hid, title, items in (
        ("unplaced", "Unplaced stations and why", unplaced),
        ("uncertain", "Kept links that are uncertain", uncertain),
        ("rejected", "Rejected links", rejected),
        ("map-conflicts", "Placed stations that contradicted each other (map check)", conflicts),
    ):
        body = f"<ul>{''.join(items)}</ul>" if items else "<p>none</p>"
        out.append(f'<div id="{hid}"><h3>{_e(title)} ({len(items)})</h3>{body}</div>')
    out.append("</section>")
    return "".join(out)


def _groups_section(doc: Mapping[str, Any], f: ReportFigures) -> str:
    reference = str(doc.get("reference", ""))
    rows = [
        "<tr>"
        + _cell(str(g), g)
        + _cell(str(len(stems)), len(stems))
        + _cell(f.group_frames.get(g, "–"))
        + _cell("yes" if f.group_frames.get(g) == reference else "no")
        + _cell(", ".join(stems), cls="text")
        + "</tr>"
        for g, stems in f.groups.items()
    ]
    headers = (
        ("group", "connected group number"),
        ("stations", "how many stations it holds"),
        ("frame", "the station whose frame its poses are in"),
        ("reference", "whether it is the reference's group"),
        ("members", "its stations"),
    )
    note = (
        "<p>Groups that no accepted link joins are never fused: each keeps its own frame, and "
        "only the reference's group is placed.</p>"
        if len(f.groups) > 1
        else ""
    )
    table = _table("group-table", headers, rows)
    return f'<section id="groups"><h2>Groups</h2>{note}{table}</section>'


DEFINITIONS = """<section id="definitions"><h2>How the figures are defined</h2><dl>
<dt>overlap</dt><dd>Share of one scan's points that the other scan explains (within the
registration's tolerance), in each direction: the denominator is the scan the column names.</dd>
<dt>inliers</dt><dd>Feature matches that agree with the link's pose / matches tested;
<em>pose from the plan view</em> when the overlay of the scans' plan views found the pose, not
feature matches (their count then says nothing about the link).</dd>
<dt>RMSE</dt><dd>Cloud-to-cloud root mean square distance of the link's inliers after the last
stage (point-to-plane when refined).</dd>
<dt>strength</dt><dd>How firmly the overlap's surfaces fix each pose parameter, per point, from
0 (not at all: a corridor along its axis) to 1; weak values are marked.</dd>
<dt>loop error</dt><dd>Of a rejected link: how far it disagrees with the loop of other links it
closes. Of an accepted link: how far its own transform disagrees with the adjusted poses (the
link error): the rotation angle and the displacement of the source's origin.</dd>
<dt>bundle error</dt><dd>Root mean square of the accepted links' errors; mean and max link error
over the same links.</dd>
<dt>group</dt><dd>Stations joined by accepted links. A group no link joins to the reference's
keeps its own frame and is not placed.</dd>
<dt>map check</dt><dd>Every pair of placed stations of a group, linked or not, scored at
its solved relative pose: when more of one station's points lie in the other's free space (in
front of what that scanner measured) than on its surfaces, one of them is placed wrongly (a wrong
link through repeating structure); the links between them that no loop confirms are cut (the
most doubtful one when loops confirm them all) and the graph solved again. A station that a
link closing no loop places is also tested against the stations loops confirm on every pixel of
both scans, and refuted from 0.3 % of their points in each other's open space.</dd>
<dt>verdict</dt><dd>The pairwise registration's own judgement: confident, or uncertain with
reasons (low overlap, weak axis, ambiguous pose, few or clustered inliers, free-space conflict,
high residual).</dd>
</dl></section>"""

CSS = """
body{font:14px/1.4 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;
color:#1b1b1b;background:#fafafa}
header,section{margin:0 auto;max-width:1500px;padding:8px 24px}
h1{font-size:22px;margin:16px 0 4px}h2{font-size:18px;margin:18px 0 6px}
h3{font-size:15px;margin:8px 0}
.outcome{font-size:16px;font-weight:600;padding:8px 12px;border-radius:6px}
.outcome.confident{background:#d9f2e9}.outcome.uncertain{background:#fcecc9}
.outcome.failed{background:#f8d5c6}
.kpis{display:flex;flex-wrap:wrap;gap:8px}
.kpi{background:#fff;border:1px solid #ddd;border-radius:6px;padding:6px 10px;min-width:110px}
.kpi .v{font-size:17px;font-weight:600}.kpi .l{font-size:12px;color:#555}
figure{margin:0;background:#fff;border:1px solid #ddd;border-radius:6px;padding:8px}
figure svg{display:block;max-width:100%;height:auto;margin:0 auto}
figcaption{font-size:12px;color:#444}
.scroll{overflow-x:auto}
table{border-collapse:collapse;background:#fff;font-size:12.5px;white-space:nowrap}
th,td{border:1px solid #ddd;padding:3px 6px;text-align:right}
th{background:#eee;text-align:center;cursor:pointer;user-select:none;white-space:normal;min-width:36px}
th.asc::after{content:" \\25B2"}th.desc::after{content:" \\25BC"}
td.text{text-align:left;white-space:normal;min-width:220px;max-width:560px}
#link-table td:nth-child(-n+6),#station-table td:first-child{text-align:left}
tr.rejected,tr.unplaced{background:#fbe3d9}tr.uncertain{background:#fdf3dc}
tr.failed{background:#eee}
td.weak{color:#b03a00;font-weight:700}
.k-confident{color:#00704f}.k-uncertain{color:#a36a00}.k-rejected{color:#b03a00;font-weight:700}
.k-failed{color:#555}
dt{font-weight:600}dd{margin:0 0 6px 16px}
footer{max-width:1500px;margin:0 auto;padding:12px 24px;color:#666;font-size:12px}
"""

#: sorts a table by the column whose header is clicked (numbers by value, text by text)
JS = """
document.querySelectorAll("table.sortable th").forEach(function (th, col) {
  th.addEventListener("click", function () {
    var table = th.closest("table"), body = table.tBodies[0];
    var asc = !th.classList.contains("asc");
    table.querySelectorAll("th").forEach(function (h) { h.classList.remove("asc", "desc"); });
    th.classList.add(asc ? "asc" : "desc");
    var key = function (tr) {
      var td = tr.children[col];
      if (!td) return null;
      var v = td.hasAttribute("data-sort") ? td.getAttribute("data-sort") : td.textContent;
      if (v === "" || v === "\u2013") return null;
      var n = Number(v);
      return isNaN(n) ? v.toLowerCase() : n;
    };
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {
      var x = key(a), y = key(b), c;
      if (x === null || y === null) return (x === null) - (y === null);  // missing: last
      if (typeof x === typeof y) c = x < y ? -1 : x > y ? 1 : 0;
      else c = typeof x === "number" ? -1 : 1;
      return asc ? c : -c;
    });
    rows.forEach(function (r) { body.appendChild(r); });
  });
});
"""


def _caption(doc: Mapping[str, Any], f: ReportFigures) -> str:
    st = doc["stations"]
    panel = {s: g for g, stems in drawn_groups(doc, f).items() for s in _xy(doc, stems)}
    hidden = sum(
        1 for lk in doc["links"] if panel.get(lk["target"], -1) != panel.get(lk["source"], -2)
    )
    text = (
        "Plan view of the stations (x, y in metres, each group in its own frame); links "
        "coloured by status, rejected links dashed and labelled with their loop error."
    )
    if hidden:
        text += f" {_plural(hidden, 'link')} not drawn: an end is not drawn or in another group."
    missing = [s for s in st if s not in panel]
    if missing:
        text += f" Not drawn (no pose, or alone in its group): {', '.join(missing)}."
    return text


def render_report(poses_doc: Mapping[str, Any], *, title: str = "Survey report") -> str:
    """The survey report as one self-contained HTML page (see the module's docstring).

    Parameters
    ----------
    poses_doc : dict
        A poses document (``DIR/poses.json``, schema in :mod:`flexreg.survey`): at least
        ``"stations"`` (stem -> ``T_reference_station`` 4x4 or None, ``placed``, ``group``,
        ...) and ``"links"`` (``target``, ``source``, ``T_target_source``, ``status``,
        ``verdict``, ``overlap``, ``rmse_m``, ``loop_error_deg``, ``loop_error_m``,
        ``strength``, ...).
    title : str
        The page's heading.

    Returns
    -------
    str
        The page; every text taken from the document is HTML-escaped.

    Raises
    ------
    InputError
        The document does not follow the schema (no stations, a link naming an unknown
        station, a transform that is not a finite 4x4 matrix).
    """
    check_document(poses_doc)
    errs = link_errors(poses_doc)
    f = report_figures(poses_doc, errs)
    weak = weak_axis_threshold(poses_doc)
    links = poses_doc["links"]
    link_rows = [
        _link_row(i, lk, e, weak) for i, (lk, e) in enumerate(zip(links, errs, strict=True))
    ]
    problems = "".join(f"<li>{_e(p)}</li>" for p in f.problems)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title><style>{CSS}</style></head><body>",
        f"<header><h1>{_e(title)}</h1><p>{_plural(f.stations, 'station')}, "
        f"{_plural(len(links), 'link')}; poses in the frame of "
        f"<b>{_e(poses_doc.get('reference', '–'))}</b>.</p></header>",
        _summary_section(poses_doc, f),
        f'<section id="problems"><h2>Problems reported</h2><ul>{problems}</ul></section>'
        if problems
        else "",
        _attention_section(poses_doc, f),
        '<section id="graph"><h2>Station graph</h2><figure id="station-graph">'
        f"{station_graph_svg(poses_doc, f)}<figcaption>{_e(_caption(poses_doc, f))}"
        "</figcaption></figure></section>",
        f'<section id="links"><h2>Links ({len(links)})</h2><p>Click a column heading to sort. '
        f"Strength below {weak:g} is marked weak.</p>"
        f"{_table('link-table', LINK_HEADERS, link_rows)}</section>",
        f'<section id="stations"><h2>Stations ({f.stations})</h2>'
        f"{_table('station-table', STATION_HEADERS, _station_rows(poses_doc, errs))}</section>",
        _groups_section(poses_doc, f),
        DEFINITIONS,
        "<footer>Written by flexreg survey. T_reference_station maps a station's points into "
        "the reference frame; T_target_source maps the source's points into the target's "
        "frame. Angles in degrees, distances in metres unless a column says mm.</footer>",
        f"<script>{JS}</script></body></html>",
    ]
    return "\n".join(p for p in parts if p) + "\n"


def write_report(
    poses_doc: Mapping[str, Any], out_html: Path, *, title: str = "Survey report"
) -> Path:
    """Write :func:`render_report`'s page to ``out_html`` atomically (a temporary sibling
    renamed into place: nobody ever sees half a page, and a failed render writes nothing).

    Returns
    -------
    Path
        ``out_html``.

    Raises
    ------
    InputError
        The document does not follow the schema, or ``out_html`` cannot be written.
    """
    page = render_report(poses_doc, title=title)
    out = Path(out_html)

    def write(tmp: Path) -> None:
        try:
            tmp.write_text(page, encoding="utf-8")
        except OSError as e:
            raise InputError(out, f"cannot write: {e.strerror or e}") from e

    try:
        atomic_write(out, write)
    except OSError as e:  # the folder cannot be made
        raise InputError(out, f"cannot write: {e.strerror or e}") from e
    log.info("survey report written to %s", out)
    return out
