"""Running the milling cell and reading the result: the simulation, the
laser scan of the machined surface, and the surface-error statistics."""

import time
from dataclasses import dataclass

import numpy as np

from robstiff_drake.diagrams.milling_cell import build_milling_cell, make_simulator, tool_wrench_log
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.path_elements import Line
from robstiff_drake.model.spindle import spindle_power_W, spindle_torque_Nm
from robstiff_drake.model.surface import envelope_heights, envelope_heights_at, surface_error_stats
from robstiff_drake.progress import simulation_bar, time_monitor

# How long after the path ends the simulation goes on (s): lets the last
# correction settle; the scan only covers the material anyway.
RUN_OUT_S = 0.1


@dataclass
class ScanLine:
    """One scan line: along x at ``y_m``, or (``s_m`` given) along the path's
    centre line shifted ``offset_m`` to the left of the feed, at points
    (x_m, y_points_m) that lie s_m along the path."""

    y_m: float
    x_m: np.ndarray
    commanded_m: np.ndarray  # NaN where there is no machined face (gaps)
    machined_m: np.ndarray  # the true machined surface (the simulation's truth)
    measured_m: np.ndarray = None  # what the scanner reads: machined + its noise (scan.noise_mm)
    s_m: np.ndarray = None  # arc length along the path (path scans)
    y_points_m: np.ndarray = None  # each point's y (path scans)
    offset_m: float = 0.0

    @property
    def error_m(self):
        """Surface error, positive where more was removed than commanded."""
        return self.commanded_m - self.machined_m

    @property
    def measured_error_m(self):
        """The surface error as the scan measures it (with the scanner's noise)."""
        return self.commanded_m - (self.machined_m if self.measured_m is None else self.measured_m)

    @property
    def y_at(self):
        """Each point's y (m)."""
        return self.y_points_m if self.y_points_m is not None else np.full(self.x_m.shape, self.y_m)


@dataclass
class RunResult:
    compensation: bool
    logs: dict  # name -> (times (N,), data (N, k))
    scans: list
    surface_error_mm: dict
    sim_seconds: float
    wall_seconds: float
    cell: object = None
    spindle: dict = None  # power_W_max, power_W_mean (while cutting), torque_Nm_max
    cpu_seconds: float = None  # the process's CPU time (all its threads) in the simulation alone

    @property
    def realtime_factor_cpu(self):
        """Simulated s per CPU s of the simulation alone (None if not measured)."""
        return self.sim_seconds / self.cpu_seconds if self.cpu_seconds else None

    @property
    def realtime_factor(self):
        return self.sim_seconds / self.wall_seconds if self.wall_seconds > 0 else float("inf")


def material_top(workpiece, x, y):
    """Top of the uncut material at (x, y) (m); NaN where there is none."""
    top = np.full(np.shape(x), -np.inf)
    for (x0, x1), (y0, y1), zt in zip(workpiece.x_m, workpiece.y_m, workpiece.top_m):
        inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        top = np.where(inside, np.maximum(top, zt), top)
    return np.where(np.isfinite(top), top, np.nan)


def scan_lines(cell):
    sc = cell.scenario
    if sc.scan.lines_y_mm:
        return [y / 1e3 for y in sc.scan.lines_y_mm]
    return sorted({float(np.mean(yr)) for yr in cell.workpiece.y_m})


def scanner_noise_m(scan_config, compensation, line_index, n):
    """The scanner's height noise (m) for ``n`` points of one scan line:
    Gaussian, 1 sigma ``scan.noise_mm``, from a stream fixed by the scan's
    seed, the cut (with or without compensation) and the line."""
    rng = np.random.default_rng([int(scan_config.seed), int(bool(compensation)), int(line_index)])
    return rng.normal(0.0, scan_config.noise_mm / 1e3, n)


def scan_along(sc, path):
    """"x" or "path": how the scenario's surface is scanned (scan.along;
    "auto": along x when every move runs along x or straight down)."""
    if sc.scan.along != "auto":
        return sc.scan.along
    for e in path.elements:
        if not isinstance(e, Line) or abs(e.u[1]) > 1e-9 * max(1.0, abs(e.u[0])):
            return "path"
    return "x"


def inside_margin(workpiece, x, y, margin):
    """Points at least ``margin`` (m) inside some box's edges."""
    ok = np.zeros(np.shape(x), dtype=bool)
    for (x0, x1), (y0, y1) in zip(workpiece.x_m, workpiece.y_m):
        ok |= (x >= x0 + margin) & (x <= x1 - margin) & (y >= y0 + margin) & (y <= y1 - margin)
    return ok


def scan_along_path(cell, p_cmd, n_cmd, p_act, n_act, R):
    """Scan lines along the commanded path's centre line (and at the
    scenario's offsets across it): points every scan.resolution_mm of arc
    length where the path runs within 60 degrees of horizontal."""
    sc = cell.scenario
    s, pts, tg = cell.path.sample_xy(sc.scan.resolution_mm / 1e3)
    normal = np.column_stack([-tg[:, 1], tg[:, 0]])  # left of the feed
    lines = []
    for i, off_mm in enumerate(sc.scan.offsets_mm or [0.0]):
        off = off_mm / 1e3
        x = pts[:, 0] + off * normal[:, 0]
        y = pts[:, 1] + off * normal[:, 1]
        top = material_top(cell.workpiece, x, y)
        floor = np.nan_to_num(top, nan=-np.inf)
        h_cmd = envelope_heights_at(x, y, p_cmd, n_cmd, R, floor)
        h_act = envelope_heights_at(x, y, p_act, n_act, R, floor)
        gap = ~(np.isfinite(top) & (h_cmd < top - 1e-9) & inside_margin(cell.workpiece, x, y,
                                                                        sc.scan.edge_margin_mm / 1e3))
        h_cmd[gap] = np.nan
        h_act[gap] = np.nan
        measured = h_act + scanner_noise_m(sc.scan, cell.compensation, i, len(x))
        lines.append(ScanLine(np.nan, x, h_cmd, h_act, measured, s_m=s, y_points_m=y, offset_m=off))
    return lines


def scan_surface(cell, times, q):
    """Scan lines of the surface the actual and the commanded pass leave,
    and what the scanner measures of the actual one (with its noise)."""
    sc = cell.scenario
    R = cell.force_model.cutter.radius_m
    T6 = kin.frames(cell.robot.dh, q)[:, 6]
    p_act = T6[:, :3, 3] + T6[:, :3, :3] @ cell.tool_m
    n_act = -T6[:, :3, 2]  # the tool's z axis points down the spindle
    p_cmd = cell.path.positions(times)
    n_cmd = np.tile([0.0, 0.0, 1.0], (len(times), 1))
    if scan_along(sc, cell.path) == "path":
        return scan_along_path(cell, p_cmd, n_cmd, p_act, n_act, R)
    margin = sc.scan.edge_margin_mm / 1e3
    x_lo = cell.workpiece.x_m[:, 0].min() + margin
    x_hi = cell.workpiece.x_m[:, 1].max() - margin
    x = np.arange(x_lo, x_hi + 1e-12, sc.scan.resolution_mm / 1e3)
    lines = []
    for i, y in enumerate(scan_lines(cell)):
        top = material_top(cell.workpiece, x, np.full_like(x, y))
        # at the box edges in y the scan would see the side: stay inside by the margin
        h_cmd = envelope_heights(x, y, p_cmd, n_cmd, R, np.nan_to_num(top, nan=-np.inf))
        h_act = envelope_heights(x, y, p_act, n_act, R, np.nan_to_num(top, nan=-np.inf))
        # no material, or the commanded pass does not reach it: not part of the machined face
        gap = ~(np.isfinite(top) & (h_cmd < top - 1e-9))
        h_cmd[gap] = np.nan
        h_act[gap] = np.nan
        measured = h_act + scanner_noise_m(sc.scan, cell.compensation, i, len(x))
        lines.append(ScanLine(y, x, h_cmd, h_act, measured))
    return lines


def zone_masks(cell, x):
    """Boolean masks over scan positions x (m): entry zones (the first
    ``zone`` after each box's leading edge in the feed direction), exit zones
    (the last ``zone`` before its trailing edge), and the steady rest.  The
    zone is the cutter radius unless the scenario sets scan.zone_mm."""
    zone = cell.scenario.scan.zone_mm / 1e3 or cell.force_model.cutter.radius_m
    forward = cell.path.directions[0, 0] >= 0
    entry = np.zeros(x.shape, dtype=bool)
    exit_ = np.zeros(x.shape, dtype=bool)
    for x0, x1 in cell.workpiece.x_m:
        lead, trail = (x0, x1) if forward else (x1, x0)
        sign = 1.0 if forward else -1.0
        entry |= (sign * (x - lead) >= 0) & (sign * (x - lead) <= zone)
        exit_ |= (sign * (trail - x) >= 0) & (sign * (trail - x) <= zone)
    return entry, exit_, ~(entry | exit_)


def path_zone_masks(cell, line):
    """Entry / exit / steady masks of a scan along the path: the first and
    last ``zone`` (m of arc length) of every stretch of machined face."""
    zone = cell.scenario.scan.zone_mm / 1e3 or cell.force_model.cutter.radius_m
    face = np.isfinite(line.error_m)
    entry = np.zeros(face.shape, dtype=bool)
    exit_ = np.zeros(face.shape, dtype=bool)
    edges = np.flatnonzero(np.diff(np.r_[0, face.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):  # stretches [a, b)
        s = line.s_m[a:b]
        entry[a:b] = s - s[0] <= zone
        exit_[a:b] = s[-1] - s <= zone
    return entry, exit_, ~(entry | exit_)


def zone_stats(cell, scans):
    """Largest |error| (mm) in the entry and exit zones, and the steady part's
    mean and largest |error|."""
    out = {}
    parts = {"entry": [], "exit": [], "steady": []}
    for line in scans:
        masks = path_zone_masks(cell, line) if getattr(line, "s_m", None) is not None else zone_masks(cell, line.x_m)
        for name, m in zip(("entry", "exit", "steady"), masks):
            e = line.error_m[m]
            parts[name].append(e[np.isfinite(e)])
    for name, chunks in parts.items():
        e = np.concatenate(chunks) * 1e3 if chunks else np.zeros(0)
        out[f"{name}_max_abs"] = float(np.max(np.abs(e))) if e.size else 0.0
        if name == "steady":
            out["steady_mean"] = float(e.mean()) if e.size else 0.0
    return out


def scanned_surface(cell, times, q):
    """(scan lines, surface-error statistics mm incl. the entry/exit zones)
    of the cut made by link angles ``q`` (N, 6 rad) at ``times`` (s)."""
    scans = scan_surface(cell, times, q)
    err = np.concatenate([s.error_m[np.isfinite(s.error_m)] for s in scans])
    stats = surface_error_stats(err) if err.size else {}
    stats.update(zone_stats(cell, scans))
    return scans, stats


def run_cut(sc, robot, *, compensation=True, cell=None, progress=False):
    """Simulate scenario ``sc`` once; return logs, scans and statistics.
    ``progress``: a bar over simulated time on stderr (False: off; None: on
    a terminal; True: forced; see robstiff_drake/progress.py)."""
    cell = cell or build_milling_cell(sc, robot, compensation=compensation)
    sim = make_simulator(cell)
    t_end = cell.path.duration_s + RUN_OUT_S
    with simulation_bar(t_end, progress, "compensated" if compensation else "uncompensated") as bar:
        monitor = time_monitor(bar, t_end)
        if monitor is not None:
            sim.set_monitor(monitor)
        t0, c0 = time.perf_counter(), time.process_time()
        sim.AdvanceTo(t_end)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    root = sim.get_context()
    logs = {name: signal.read(root) for name, signal in cell.loggers.items()}
    logs["tool_wrench"] = tool_wrench_log(cell, logs)
    t, x = logs["state"]
    scans, stats = scanned_surface(cell, t, x[:, :6])
    return RunResult(compensation, logs, scans, stats, t_end, wall, cell, spindle_load(cell, logs), cpu)


def spindle_load(cell, logs):
    """The spindle's torque and power over the run, from the cutting wrench
    and the tool axis (the flange z axis) at the logged link angles."""
    t, w = logs["cutting_wrench"]
    ts, x = logs["state"]
    i = np.clip(np.searchsorted(ts, t), 0, len(ts) - 1)
    axis = kin.frames(cell.robot.dh, x[i, :6])[:, 6, :3, 2]
    torque = spindle_torque_Nm(w, axis)
    power = spindle_power_W(torque, cell.scenario.cutter.spindle_rpm)
    cutting = power > 1.0
    return {"power_W_max": float(power.max()) if power.size else 0.0,
            "power_W_mean": float(power[cutting].mean()) if np.any(cutting) else 0.0,
            "torque_Nm_max": float(torque.max()) if torque.size else 0.0}
