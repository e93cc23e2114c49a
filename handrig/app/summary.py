"""The run summary: a session's figures as one JSON-able object, and as text.

:func:`summary_dict` is what ``--json`` prints (per hand: the loop's statistics, the
bus's and the glove's counters, the outputs, the clamps); :func:`format_summary` the
same for a person, :func:`format_hands_summary` a part per hand when a session ran
several. The session (:mod:`handrig.app.session`) adds what only it knows (servos
left out and admitted, the torque-off read back, the stage timings, the error).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from handrig.devices.glove import GloveStats
from handrig.loop.stats import RunStats
from handrig.outputs.base import SUMMARY_KEYS_WHEN_OFF, Output
from handrig.pose.pipeline import PosePipeline

FAULT_WORDS: dict[str, str] = {
    "timeouts": "read timeouts",
    "host_timeouts": ("of them the host's (this process woke 1 ms or more after the "
                      "deadline, the host's tasks waited 1 ms for a CPU meanwhile, or the "
                      "reply came in whole after the latest a servo could have sent it: held "
                      "on its way, not lost on the bus)"),
    "retries": "read retries",
    "crc_errors": "replies with a bad CRC",
    "malformed": "malformed replies",
    "status_errors": "readings refused by a servo",
    "fallbacks": "fallbacks to plain Sync Read",
    "watchdog_trips": "Bus Watchdog trips",
    "watchdog_gaps": "writes close to the Bus Watchdog",
    "late_replies": "late replies dropped",
    "partial_replies": "Fast Sync Read replies cut short",
    "chain_ends": "reads asking silent servos last",
    "skipped_reads": "reads skipped (no room on the wire)",
    "stale_readings": "stale servo readings",
    "hardware_errors": "servo hardware errors",
    "reboots": "servo reboots",
}
"""Bus counters that are faults, as the summary names them (in this order)."""

TOP_CLAMPED = 3  # joints named in the summary's clamp line


def bus_faults(bus: dict[str, Any]) -> dict[str, int]:
    """The non-zero fault counters of a summary's ``bus`` figures, named in words."""
    return {FAULT_WORDS[k]: int(bus[k]) for k in FAULT_WORDS if bus.get(k)}


def clamped_joints(pipeline: PosePipeline, top: int = TOP_CLAMPED) -> list[dict[str, Any]]:
    """The servo joints whose targets were clamped most often (most first, none at 0)."""
    counts = np.asarray(pipeline.servo_clamps_by_servo, dtype=np.int64)
    joints = tuple(pipeline.servo_joints)
    order: list[int] = np.argsort(-counts, kind="stable")[:top].tolist() if counts.size else []
    return [{"joint": joints[i], "clamps": int(counts[i])} for i in order if counts[i] > 0]


def outputs_summary(outs: Sequence[Any], duration_s: float = 0.0) -> dict[str, Any]:
    """What a run sent besides the servos, each output's part under its own key
    (:meth:`handrig.outputs.base.Output.summary`: ``vmc``, ``recording``,
    ``glove_take``, ...); the keys of :data:`~handrig.outputs.base.SUMMARY_KEYS_WHEN_OFF`
    None when off, no other key for an output that did not run."""
    out: dict[str, Any] = dict.fromkeys(SUMMARY_KEYS_WHEN_OFF)
    for o in outs:
        if isinstance(o, Output):
            key, figures = o.summary(duration_s)
            out[key] = figures
    return out


def summary_dict(stats: RunStats, bus_stats: Any, glove_stats: GloveStats | None,
                 torque_off: bool | None,
                 *, outputs: dict[str, Any] | None = None,
                 clamped: list[dict[str, Any]] | None = None, ease_s: float = 0.0
                 ) -> dict[str, Any]:
    """The run's figures as one JSON-able object (the keys ``handrig demo --json`` promises).

    ``outputs``: :func:`outputs_summary`; ``clamped``: :func:`clamped_joints`;
    ``ease_s``: how long the run eased to the relaxed pose at its end (included in
    ``frames`` and ``duration_s``; 0 when it ended at once)."""
    s = stats

    def num(x: float, nd: int = 3) -> float | None:
        return None if x is None or not math.isfinite(x) else round(float(x), nd)
    out: dict[str, Any] = {
        "frames": s.frames,
        "duration_s": num(s.duration_s),
        "rate_hz": num(s.rate_hz, 2),
        "jitter_us": num(s.jitter_us, 1),
        "latency_us": {"p50": num(s.latency_us(50), 1), "p99": num(s.latency_us(99), 1),
                       "max": num(s.latency_us(100), 1), "samples": s.latency.count},
        "loop_mode": s.loop_mode,
        "compute_us": {"p50": num(s.compute_us(50), 1), "p99": num(s.compute_us(99), 1),
                       "max": num(s.compute_us(100), 1)},
        "writes_per_s": num(s.rate_hz, 2),
        "reads_per_s": num(s.reads / s.duration_s if s.duration_s > 0 else math.nan, 2),
        "writes_delayed_by_reads": s.writes_delayed,
        "cycles_without_frame": s.cycles_without_frame,
        "frames_skipped": s.frames_skipped,
        "frames_in_bursts": s.frames_in_bursts,
        "frames_in_host_stalls": s.frames_in_host_stalls,
        "frames_caught_up": s.frames_caught_up,
        "ceiling_waits": s.ceiling_waits,
        "cpu_per_cycle_us": num(s.cpu_per_cycle_us, 1),
        "overruns": s.overruns,
        "overrun_max_us": num(s.overrun_max_s * 1e6, 1),
        "missed_cycles": s.missed_cycles,
        "limit_clamps": s.servo_clamps,
        "pose_clamps": s.clamps,
        "nonfinite_targets": s.nonfinite,
        "bus_clamps": s.bus_clamps,
        "slew_limited": s.slewed,
        "tracking_rms_deg": num(s.tracking_rms_deg),
        "tracking_max_deg": num(s.tracking_max_deg),
        "reads": s.reads,
        "stale_reads": s.stale_reads,
        "relax_events": s.relax_events,
        "silence": {"silences": s.servo_silences, "held": s.servos_held,
                    "recoveries": s.servo_recoveries, "admitted": s.servos_admitted,
                    **s.silence_counts},
        "heat": {"warnings": s.heat_warnings, "reliefs": s.heat_reliefs,
                 "actions": s.heat_actions, "hottest": s.hottest,
                 "max_c": [num(t, 1) for t in s.max_temperature_c]},
        "resumes": s.resumes,
        "relax_keys": s.relax_keys,
        "estop": s.estop,
        "stop_reason": s.stop_reason,
        "events": list(s.events),
        "events_total": s.events.total,
        "torque_off": torque_off,
        "ease_s": num(ease_s),
        "clamped_joints": list(clamped or []),
        "outputs": outputs if outputs is not None else dict.fromkeys(SUMMARY_KEYS_WHEN_OFF),
        "faults": {},
    }
    if glove_stats is not None:
        out["glove"] = {
            "frames_ok": glove_stats.frames_ok, "crc_errors": glove_stats.crc_errors,
            "decode_errors": glove_stats.decode_errors, "resyncs": glove_stats.resyncs,
            "seq_gaps": glove_stats.seq_gaps, "frames_used": s.glove_samples,
            "channel_errors": glove_stats.channel_errors,
            "disconnects": glove_stats.disconnects,
            "reconnects": glove_stats.reconnects,
            "last_outage_s": num(glove_stats.last_outage_s),
        }
    if bus_stats is not None:
        bus: dict[str, Any] = {}
        for k, v in vars(bus_stats).items():
            if k.startswith("_") or k == "n_servos":
                continue
            if isinstance(v, np.ndarray):
                bus[k] = int(v.sum())
            elif isinstance(v, int | float):
                bus[k] = v
        out["bus"] = bus
        out["faults"] = bus_faults(bus)
    return out


def _counts(items: dict[str, int]) -> str:
    return ", ".join(f"{n} {what}" for what, n in items.items()) if items else "none"


def _outputs_lines(outputs: dict[str, Any]) -> list[str]:
    """Each output's own line (its figures' ``said``: :meth:`handrig.outputs.base.Output.
    summary`), in the run's order; "none" when no output ran."""
    said = [part["said"] for part in outputs.values()
            if isinstance(part, dict) and part.get("said")]
    if not said:
        return ["outputs           none"]
    return [f"outputs           {said[0]}", *(f"                  {line}" for line in said[1:])]


CLAMP_RANGE_FRACTION = 0.05
"""Controls outside the map's training range in more than this fraction of frames: the
map is a likely cause of clamps."""


def clamp_advice(summary: dict[str, Any], recording: str, controls: tuple[str, ...],
                 training: Any) -> str:
    """The likely causes of the run's clamps that it can tell: a recorded performance
    (``recording``: the file a replayed or emulated glove streamed), a glove past its
    calibration (a control curve's own servo clamped), a map outside its training range
    (``training``: :meth:`handrig.pose.expand.Expander.training_range`)."""
    if not summary.get("limit_clamps"):
        return "no clamps"
    causes = []
    past = [c["joint"] for c in summary.get("clamped_joints") or [] if c["joint"] in controls]
    at = f" ({', '.join(past)}: a control asked past its joint)" if past else ""
    if recording:
        causes.append(f"a recorded performance ({recording}): the clamps come from the"
                      f" recording{at} and the map, not from a glove on a hand")
    elif past:
        causes.append(f"a glove past its calibration{at}: recalibrate the glove")
    if training.known and training.outside_fraction > CLAMP_RANGE_FRACTION:
        causes.append(f"a map outside its training range (controls beyond it in"
                      f" {training.outside_fraction:.0%} of frames; refit the map on motion"
                      " like this, or check the glove calibration)")
    if not causes:
        causes.append("the map asks for poses past the joints inside its training range"
                      " (check it with handrig evaluate)")
    return "likely: " + "; ".join(causes)


SIMULATED_LINE = ("bus               SIMULATED (--port sim): emulated servos and a MuJoCo "
                  "puppet, no hardware was driven")


def format_summary(summary: dict[str, Any]) -> str:
    """The human-readable summary of a run (the same figures as ``--json``)."""
    lat = summary["latency_us"]
    comp = summary.get("compute_us") or {}
    glove = summary.get("glove", {})
    ease_s = summary.get("ease_s") or 0.0
    ease = (f"; includes the {ease_s:g} s ease to the relaxed pose at the end" if ease_s
            else "; ended at once, no ease")
    clamped = summary.get("clamped_joints") or []
    most = (", most at " + ", ".join(f"{c['joint']} ({c['clamps']})" for c in clamped)
            if clamped else "")
    lines = [
        *([SIMULATED_LINE] if summary.get("simulated_bus") else []),
        *([f"show              {summary['show']}"] if summary.get("show") else []),
        f"frames            {summary['frames']} in {summary['duration_s']} s "
        f"({summary['rate_hz']} Hz, jitter {summary['jitter_us']} us){ease}",
        f"latency           p50 {lat['p50']} us, p99 {lat['p99']} us, max {lat['max']} us "
        "(glove frame's arrival -> Sync Write handed to the OS)",
        f"                  of which compute p50 {comp.get('p50')} us, p99 {comp.get('p99')} us "
        f"(cycle start -> Sync Write; loop {summary.get('loop_mode', 'fixed')})",
        *([f"servos left out   {', '.join(summary['servos_left_out'])} (did not answer at "
            "start-up: no goal, no torque until commissioned)"]
          if summary.get("servos_left_out") else []),
        *([f"  admitted        {', '.join(summary['servos_admitted'])} (answered later: "
            "commissioned, eased in from where it was)"]
          if summary.get("servos_admitted") else []),
        f"frame losses      {summary.get('frames_skipped', 0)} skipped by the loop, "
        f"{summary.get('frames_in_host_stalls', 0)} left waiting by host stalls (the host "
        "read nothing for 3 frame periods or more: not the glove), "
        f"{summary.get('frames_in_bursts', 0)} lost in the glove's own bursts (caught up: "
        f"{summary.get('frames_caught_up', 0)} written just before a newer one)",
        f"overruns          {summary['overruns']} (max {summary['overrun_max_us']} us late, "
        f"{summary['missed_cycles']} cycles missed)",
        f"limit clamps      {summary['limit_clamps']} servo targets held at a joint or servo "
        f"limit{most}",
        *([] if not (summary["limit_clamps"] or summary.get("clamped_joints")
                     or summary.get("clamp_advice", "no clamps") != "no clamps") else [
            "                  (the pose asked past the limit: normal at a full fist or spread"
            + (f"; high all the time: {summary['clamp_advice']})" if "clamp_advice" in summary
               else ")")]),
        f"                  {summary['pose_clamps']} values of the full two-hand pose clamped, "
        f"{summary['bus_clamps']} goals clamped by the driver, {summary['slew_limited']} "
        f"slew-limited, {summary['nonfinite_targets']} non-finite targets held",
        f"take              {glove.get('frames_ok', '-')} frames played, used "
        f"{glove.get('frames_used', '-')}" if summary.get("take_played") else
        f"glove             {glove.get('frames_ok', '-')} frames ok, "
        f"{glove.get('crc_errors', 0)} CRC errors, {glove.get('decode_errors', 0)} other "
        f"errors, {glove.get('resyncs', 0)} resyncs, used {glove.get('frames_used', '-')}",
        f"faults            {_counts(summary.get('faults', {}))}",
        f"tracking          rms {summary['tracking_rms_deg']} deg, max "
        f"{summary['tracking_max_deg']} deg (present vs goal, {summary['reads']} reads, "
        f"{summary['stale_reads']} with stale servos)",
        *_outputs_lines(summary.get("outputs") or {}),
        *cue_lines(summary.get("cues") or {}),
        *_heat_lines(summary.get("heat") or {}),
        f"safety            {summary['relax_events']} relax events (glove lost or servos "
        f"silent), {summary.get('relax_keys', 0)} by the relax key, "
        f"{summary.get('resumes', 0)} resumes, e-stop "
        f"{'pressed' if summary['estop'] else 'not pressed'}, stopped: {summary['stop_reason']}",
        f"torque off        {summary['torque_off']}",
        *([f"  not confirmed   {'; '.join(summary['torque_off_unconfirmed'])}"]
          if summary.get("torque_off_unconfirmed") else []),
        *([f"  note            {summary['torque_off_note']}"]
          if summary.get("torque_off_note") else []),
    ]
    if "error" in summary:
        lines.append(f"error             {summary['error']}")
    return "\n".join(lines)


def format_hands_summary(summary: dict[str, Any]) -> str:
    """The summary of a two-hand run: a part per hand, then torque and the error."""
    lines = [*([SIMULATED_LINE] if summary.get("simulated_bus") else []),
             *([f"show              {summary['show']}"] if summary.get("show") else [])]
    for name, part in summary["hands"].items():
        part = {k: v for k, v in part.items() if k not in ("show", "simulated_bus")}
        lines.append(f"--- {name} hand ({part.get('glove_source') or 'glove'}) ---")
        lines += [line for line in format_summary(part).splitlines()
                  if not line.startswith(("torque off", "error"))]
    lines += cue_lines(summary.get("cues") or {})
    lines.append(f"torque off        {summary['torque_off']} (every servo of both hands)")
    if summary.get("torque_off_note"):
        lines.append(f"  note            {summary['torque_off_note']}")
    if "error" in summary:
        lines.append(f"error             {summary['error']}")
    return "\n".join(lines)


CUE_EVENTS_SHOWN = 12


def cue_lines(cues: dict[str, Any]) -> list[str]:
    """The ``cues`` part (:meth:`handrig.app.cues.live.LiveCues.summary`): the counts, the
    cues' events (the first few; all of them in ``--json``) and the takes they made."""
    if not cues:
        return []
    where = " ".join(w for w in (f"OSC on {cues['osc_in']}" if cues.get("osc_in") else "",
                                 f"MIDI from {cues['midi_in']}" if cues.get("midi_in")
                                 else "") if w)
    sources = ", ".join(f"{k} {v}" for k, v in (cues.get("by_source") or {}).items())
    lines = [f"cues              {cues['received']} received ({sources or 'none'}): "
             f"{cues['acted']} acted, {cues['refused']} refused; ignored "
             f"{cues['unknown']} unknown, {cues['malformed']} malformed, "
             f"{cues['unmapped']} unmapped" + (f" ({where})" if where else "")]
    events = cues.get("events") or []
    lines += [f"                {e}" for e in events[:CUE_EVENTS_SHOWN]]
    more = cues.get("events_total", len(events)) - min(len(events), CUE_EVENTS_SHOWN)
    if more > 0:
        lines.append(f"                  ... {more} more (--json keeps the last "
                     f"{len(events)})")
    for take in (cues.get("takes") or {}).get("done", []):
        lines.append(f"  take by cue     {take['path']}: {take['frames']} frames, "
                     f"{take['duration_s']} s")
    return lines


def _heat_lines(heat: dict[str, Any]) -> list[str]:
    """The ``heat`` line: the hottest servo read and what the [heat] tiers did."""
    if not heat:
        return []
    hottest = heat.get("hottest") or "no temperature read"
    return [f"heat              hottest {hottest}; {heat.get('warnings', 0)} warnings, "
            f"{heat.get('reliefs', 0)} effort caps, {heat.get('actions', 0)} actions "
            "([heat] tiers)"]
