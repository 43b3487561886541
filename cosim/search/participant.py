"""The search in the loop: plan, fly the plan as MAVLink missions, watch for fires.

At start the participant plans the search of the scenario's area for its
aircraft (``cosim.coverage``) and puts each aircraft's plan on board as a
MAVLink mission flown in its mission mode (``MavlinkLinks.load_mission``),
so a ground station connected to the run downloads the plans and watches
them flown, and the aircraft fly them through the same command path as
every other mission. At each frame of the search camera (a whole number of
exchanges) it takes each fire near a footprint through the ground-truth
geometry (``sensing``), and at each step of the coverage map (``coverage_hz``)
every camera's footprint and the ground swept since the last step into the
map (``coverage_map``): a fire counts as detected by an aircraft once it has
been in that aircraft's view with at least ``min_pixels`` for ``dwell_s``
(consecutive frames). A detection is reported as an aircraft would report
it: the position from the camera geometry, its error against the truth,
and the size from the pixel extent.

Outputs (in ``RUN/search/``): ``plan.json`` (per aircraft: its strip, lanes,
lengths and waypoints), ``coverage.csv`` (coverage fraction at every frame),
``detections.csv`` (every aircraft's first detection of every fire),
``coverage_map.png`` (when each cell was first seen, the tracks planned, the
fires and the reports) and ``coverage.png`` (coverage against time); the
summary's ``search`` section holds the metrics.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from cosim.core.state import STATE_INDEX
from cosim.renderer.frame import probe_offsets
from cosim.renderer.targets import TargetSet
from cosim.search import sensing
from cosim.search.coverage_map import CoverageMap
from cosim.search.spec import SearchSpec
from cosim.sync.participants import ParticipantFailed, RunContext

log = logging.getLogger(__name__)

#: coverage fractions whose first time is reported
MILESTONES = (0.5, 0.9, 0.95, 0.99, 0.999)


#: the search's own MAVLink identity (a ground station's system id range)
SEARCH_SYSID, SEARCH_COMPID = 254, 191


class SearchParticipant:
    name = "search"

    def __init__(self, scenario: Any) -> None:
        self.scn = scenario
        self.spec: SearchSpec = scenario.sections["search"]
        self.rows = np.array(self.spec.rows, dtype=np.int64)
        self.plan: Any = None
        self.cmap: CoverageMap | None = None
        self.curve: list[tuple[float, float]] = []  # (time_s, fraction) per frame
        self.detections: list[dict[str, Any]] = []  # each aircraft's first of each fire
        self.first: dict[str, dict[str, Any]] = {}  # fire id -> its first detection
        self.frames = 0
        self.image: Any = None  # the image detector on board (``onboard``), if asked

    def prepare(self, ctx: RunContext) -> None:
        """With ``detection.image``: a tap on the cameras' frames (before they start)."""
        from cosim.search.onboard import ImageSearch
        from cosim.search.spec import cameras_for

        if self.spec.detection.image and ctx.frame_taps is not None:
            views = cameras_for(self.scn.sections, self.scn.rates.control_every,
                                self.spec.rows)
            if views:
                self.image = ImageSearch(self, views)
                ctx.frame_taps.append((self.image.tap, None))

    # --- start: the plan, on board --------------------------------------------------
    def start(self, ctx: RunContext) -> None:
        from cosim.coverage import swath_m, turn_radius_m
        from cosim.search.mission import ACCEPT_M, plan_search

        s, scn = self.spec, self.scn
        self.ctx = ctx
        self.out = ctx.out_dir / "search"
        if self.out.is_symlink():  # never written through: it may point anywhere
            self.out.unlink()
        elif self.out.is_dir():  # a previous run's: never mixed with this one's
            shutil.rmtree(self.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.ground = scn.origin.ground_alt_m
        self.swath = swath_m(s.alt_agl_m, s.camera.hfov_deg)
        self.radius = turn_radius_m(s.airspeed_mps, s.bank_deg)
        starts = [(float(ctx.start_ned_m[r, 0]), float(ctx.start_ned_m[r, 1]),
                   scn.vehicles[r].heading_deg) for r in s.rows]
        try:  # (checked when the scenario was read: this is the same plan)
            self.plan = plan_search(s, starts)
        except ValueError as e:
            raise ParticipantFailed(ValueError(f"search: cannot plan the area: {e}"),
                                    {"error": str(e)}) from None
        #: lanes flown this far past their ends (the aircraft turns early into
        #: the next lane: the lane's end would not come under the camera)
        self.accept_m = ACCEPT_M
        self.overrun = s.lane_overrun_m if s.lane_overrun_m is not None else ACCEPT_M
        self.extra_m = np.zeros(len(s.rows))
        self._load_missions(ctx)
        self.planned_s = max(a.length_m + x for a, x in zip(self.plan.aircraft, self.extra_m)) \
            / s.airspeed_mps
        self._write_plan()
        self.cmap = CoverageMap(s.area_ne, s.no_fly_ne, s.cell_m)
        #: ticks between coverage steps (each the ground swept since the last)
        self.cov_every = s.coverage_every
        # the fires, placed as the renderer places targets
        ids = [f.id for f in s.fires]
        specs = [t for t in scn.world.targets if t.id in ids]
        self.fire_specs = specs
        self.decoy = np.array([f.decoy for f in s.fires], dtype=bool)
        self.targets = TargetSet(tuple(specs), ctx.frame, self.ground)
        self.fire_ne = np.column_stack([self.targets.north_m, self.targets.east_m]) \
            if specs else np.zeros((0, 2))
        self.seen = np.zeros((len(self.rows), len(specs)), dtype=np.int32)  # dwell frames
        self.reported = np.zeros((len(self.rows), len(specs)), dtype=bool)
        self.prev_fp: np.ndarray | None = None
        self.prev_ne: np.ndarray | None = None
        self.flown = np.zeros(len(self.rows))
        self.rng = np.random.default_rng([int(scn.seed), 0x5EA2C4, 2])
        from cosim.vehicles import get_class

        #: each search aircraft's camera height above its reference point
        self.lift_m = {ctx.ids[int(r)]: float(get_class(
            scn.vehicles[int(r)].vehicle_class).camera_height_m) for r in self.rows}
        if self.image is not None:
            self.image.start(ctx.ids)
        log.info("search: %d aircraft, %.0f km2, %.0f m AGL (swath %.0f m, turns %.0f m), "
                 "plan done at %.0f s; %d fire(s)", len(self.rows), self.cmap.cells
                 * s.cell_m ** 2 / 1e6, s.alt_agl_m, self.swath, self.radius, self.planned_s,
                 len(specs))

    def _load_missions(self, ctx: RunContext) -> None:
        from cosim.mavlink import adapter as mav
        from cosim.mavlink.mission import MAX_ITEMS, MissionItem
        from cosim.search.mission import mission_waypoints

        s = self.spec
        if ctx.mavlink is None:
            raise ParticipantFailed(RuntimeError("search: the plans are flown as MAVLink "
                                                 "missions, and this run has no MAVLink"))
        # the aircraft may bank more than the plan's turns need (room to follow
        # them): ROLL_LIMIT_DEG set as a ground station sets it
        address = {v.row: (k, v.sysid) for k, specs in enumerate(ctx.mavlink.specs)
                   for v in specs}
        for row in self.spec.rows:
            if row in address:
                link, sysid = address[row]
                ctx.mavlink.inject(mav.make_message(
                    "PARAM_SET", SEARCH_SYSID, SEARCH_COMPID, target_system=sysid,
                    target_component=1, param_id="ROLL_LIMIT_DEG", param_value=s.flown_bank_deg,
                    param_type=mav.MAV_PARAM_TYPE_REAL32), link)
        for k, a in enumerate(self.plan.aircraft):
            row = int(self.rows[k])
            try:  # (checked when the scenario was read)
                wps, extra = mission_waypoints(a, s.turn_step_m, self.overrun, MAX_ITEMS)
            except ValueError as e:
                raise ParticipantFailed(ValueError(f"search: {ctx.ids[row]}: {e}"),
                                        {"error": str(e)}) from None
            self.extra_m[k] = extra
            lat, lon = ctx.frame.place(np.array([w[0] for w in wps]),
                                       np.array([w[1] for w in wps]), self.ground)
            items = [MissionItem(1, mav.MAV_FRAME_MISSION, mav.MAV_CMD_DO_CHANGE_SPEED,
                                 param1=0.0, param2=s.airspeed_mps, param3=-1.0)]
            items += [MissionItem(i + 2, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
                                  mav.MAV_CMD_NAV_WAYPOINT, param2=self.accept_m,
                                  x=round(float(la) * 1e7), y=round(float(lo) * 1e7),
                                  z=s.alt_agl_m)
                      for i, (la, lo) in enumerate(zip(lat, lon))]
            try:
                on = ctx.mavlink.load_mission(row, items, fly=True)
            except ValueError as e:  # a vehicle that flies no missions
                raise ParticipantFailed(ValueError(f"search: {e}")) from None
            if not on:
                raise ParticipantFailed(RuntimeError(
                    f"search: vehicle {ctx.ids[row]} is not on MAVLink (the scenario's "
                    f"mavlink.vehicles leaves it out); its plan is flown as a mission"))

    def _write_plan(self) -> None:
        s, p = self.spec, self.plan
        doc = {"airspeed_mps": s.airspeed_mps, "bank_deg": s.bank_deg,
               "alt_agl_m": s.alt_agl_m, "swath_m": self.swath,
               "turn_radius_m": self.radius, "lane_spacing_m": p.lane_spacing_m,
               "sweep_deg": p.sweep_deg, "completion_s": self.planned_s,
               "aircraft": [{"vehicle": self.ctx.ids[int(self.rows[k])],
                             "area_km2": a.area_m2 / 1e6, "lanes": len(a.lanes),
                             "transit_m": a.transit_m, "survey_m": a.survey_m,
                             "turns_m": a.turns_m, "overrun_m": self.extra_m[k],
                             "length_m": a.length_m + self.extra_m[k],
                             "done_s": (a.length_m + self.extra_m[k]) / s.airspeed_mps,
                             "lanes_ne": [[[q[1], q[0]] for q in lane] for lane in a.lanes]}
                            for k, a in enumerate(p.aircraft)]}
        (self.out / "plan.json").write_text(json.dumps(doc, indent=1))

    # --- every exchange ---------------------------------------------------------------
    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        cover = tick % self.cov_every == 0
        look = tick % self.spec.camera.frame_every == 0
        if self.image is None and not (cover or look):
            return
        st = states[self.rows]
        if self.image is not None:
            self.image.remember(tick, st)
        if not (cover or look):
            return
        idx = STATE_INDEX
        lat, lon, alt = (st[:, idx[k]] for k in ("lat_deg", "lon_deg", "alt_msl_m"))
        n, e, _ = self.ctx.frame.geodetic_to_ned(lat, lon, alt)
        ne = np.column_stack([n, e])
        height = alt - self.ground
        t = tick / self.ctx.physics_hz
        fp = sensing.footprints(self.spec.camera, height, st[:, idx["roll_deg"]],
                                st[:, idx["pitch_deg"]], st[:, idx["yaw_deg"]])
        if cover:
            self._cover(t, fp + ne[:, None, :], ne)
        if look and len(self.fire_specs):
            reach = np.sqrt((fp ** 2).sum(axis=2)).max(axis=1)
            self._look(tick, t, st, ne, reach)

    def _cover(self, t: float, fp: np.ndarray, ne: np.ndarray) -> None:
        """The ground under every camera (footprints ``fp``), with what it
        swept since the last step where the two footprints overlap, into the
        map."""
        import cv2

        assert self.cmap is not None
        polys = []
        for i in range(len(fp)):
            if self.prev_fp is not None:
                a, b = self.prev_fp[i].astype(np.float32), fp[i].astype(np.float32)
                area, _ = cv2.intersectConvexConvex(cv2.convexHull(a), cv2.convexHull(b))
                if area > 0:  # contiguous: the hull of both is what was swept
                    polys.append(np.vstack([self.prev_fp[i], fp[i]]))
                    continue
            polys.append(fp[i])  # apart (a slow camera, a fast turn): gaps stay gaps
        self.cmap.add(self.frames, polys)
        if self.prev_ne is not None:
            self.flown += np.hypot(*(ne - self.prev_ne).T)
        self.prev_fp, self.prev_ne = fp, ne
        self.curve.append((t, self.cmap.fraction))
        self.frames += 1

    def _look(self, tick: int, t: float, st: np.ndarray, ne: np.ndarray, reach: np.ndarray
              ) -> None:
        s, cam = self.spec, self.spec.camera
        now = [f.at(t) for f in self.fire_specs]
        sizes = np.array([max(f.length_m, f.width_m) for f in now])
        offsets = probe_offsets(now)
        hits = np.zeros_like(self.seen, dtype=bool)
        sightings: dict[tuple[int, int], sensing.Sighting] = {}
        for i, j in sensing.candidates(ne, reach, self.fire_ne, sizes).tolist():
            pose = sensing.pose_of(cam, st[i], STATE_INDEX, self.ground)
            origin = self.targets.origins_in(pose.local, pose.local_ecef_m)[j]
            seen = sensing.fire_truth(cam, pose, origin + offsets[j, :8])
            if seen.in_view and seen.pixels >= s.detection.min_pixels:
                hits[i, j] = True
                sightings[(i, j)] = seen
        self.seen = np.where(hits, self.seen + 1, 0)
        due = (self.seen >= s.dwell_frames) & ~self.reported
        for i, j in np.argwhere(due).tolist():
            self.reported[i, j] = True
            self._detected(tick, t, i, j, st[i], sightings[(i, j)], now[j])

    def _detected(self, tick: int, t: float, i: int, j: int, row: np.ndarray,
                  seen: sensing.Sighting, fire: Any) -> None:
        s = self.spec
        assert seen.centroid_px is not None
        la, lo, size_m = sensing.report(s.camera, row, STATE_INDEX, self.ground, seen.centroid_px,
                                      seen.pixels, self.rng, s.detection.position_sigma_m,
                                      s.detection.attitude_sigma_deg)
        rn, re_, _ = self.ctx.frame.geodetic_to_ned(la, lo, self.ground)
        err = math.hypot(float(rn) - self.fire_ne[j, 0], float(re_) - self.fire_ne[j, 1])
        vid = self.ctx.ids[int(self.rows[i])]
        d = {"time_s": round(t, 3), "tick": tick, "fire": fire.id, "decoy": bool(self.decoy[j]),
             "vehicle": vid, "reported_lat_deg": round(la, 8), "reported_lon_deg": round(lo, 8),
             "reported_north_m": round(float(rn), 2), "reported_east_m": round(float(re_), 2),
             "error_m": round(err, 2), "size_m": round(float(size_m), 2),
             "true_size_m": round(max(fire.length_m, fire.width_m), 2),
             "pixels": round(seen.pixels, 1), "range_m": round(seen.range_m, 1)}
        self.detections.append(d)
        if fire.id not in self.first:
            self.first[fire.id] = d
            self.ctx.events.emit("fire_detected", tick, vehicle=vid, fire=fire.id,
                                 decoy=d["decoy"], error_m=d["error_m"], size_m=d["size_m"],
                                 reported_lat_deg=d["reported_lat_deg"],
                                 reported_lon_deg=d["reported_lon_deg"])
            log.info("search: %s %s detected by %s at %.1f s (reported %.1f m off)",
                     "decoy" if d["decoy"] else "fire", fire.id, vid, t, err)

    # --- the end ----------------------------------------------------------------------
    def finish(self, tick: int, reason: str) -> dict[str, Any] | None:
        if self.cmap is None or self.plan is None:
            return None
        self._write_csv()
        s = self.spec
        target = next((d for d in self.first.values() if not d["decoy"]), None)
        has_target = any(not f.decoy for f in s.fires)
        times = {}
        for m in MILESTONES:
            hit = next((t for t, f in self.curve if f >= m), None)
            times[f"{m:g}"] = hit
        every_s = max(1.0, round(len(self.curve) / 120) * self.cov_every
                      / self.ctx.physics_hz)
        curve = [[round(t, 2), round(f, 5)] for t, f in self.curve
                 if abs(t / every_s - round(t / every_s)) < 1e-9]
        if self.curve and (not curve or curve[-1][0] != round(self.curve[-1][0], 2)):
            curve.append([round(self.curve[-1][0], 2), round(self.curve[-1][1], 5)])
        a = self.plan
        return {
            "area_km2": round(self.cmap.cells * s.cell_m ** 2 / 1e6, 3),
            "aircraft": len(self.rows),
            "airspeed_kt": s.airspeed_kt, "bank_deg": s.bank_deg,
            "alt_agl_m": round(s.alt_agl_m, 1), "alt_from_detection": s.alt_auto,
            "swath_m": round(self.swath, 1), "turn_radius_m": round(self.radius, 1),
            "lane_spacing_m": round(a.lane_spacing_m, 1),
            "plan_completion_s": round(self.planned_s, 1),
            "coverage": {"final": round(self.cmap.fraction, 5),
                         "time_to_fraction_s": times, "curve": curve,
                         "cell_m": s.cell_m},
            "target": None if not has_target else {
                "detected": target is not None,
                "time_to_detect_s": target["time_s"] if target else None,
                **({k: target[k] for k in ("vehicle", "error_m", "size_m", "true_size_m")}
                   if target else {})},
            "decoys": int(self.decoy.sum()),
            "decoys_detected": sum(1 for d in self.first.values() if d["decoy"]),
            "detections": len(self.detections),
            "first_detections": sorted(self.first.values(), key=lambda d: d["time_s"]),
            "distance_flown_km": {"total": round(float(self.flown.sum()) / 1000, 3),
                                  "per_aircraft_max": round(float(self.flown.max(initial=0))
                                                            / 1000, 3)},
            **({"image_detector": self.image.summary()} if self.image is not None else {}),
            "outputs": {k: f"search/{v}" for k, v in
                        (("plan", "plan.json"), ("coverage", "coverage.csv"),
                         ("detections", "detections.csv"), ("map", "coverage_map.png"),
                         ("curve", "coverage.png"))},
        }

    def _write_csv(self) -> None:
        with open(self.out / "coverage.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time_s", "coverage"])
            w.writerows([[f"{t:.3f}", f"{c:.6f}"] for t, c in self.curve])
        cols = ["time_s", "tick", "fire", "decoy", "vehicle", "reported_lat_deg",
                "reported_lon_deg", "reported_north_m", "reported_east_m", "error_m", "size_m",
                "true_size_m", "pixels", "range_m"]
        with open(self.out / "detections.csv", "w", newline="") as f:
            w2 = csv.DictWriter(f, cols)
            w2.writeheader()
            w2.writerows(self.detections)

    def after_run(self, out_dir: Path) -> None:
        if self.cmap is None or self.plan is None:
            return
        from cosim.search.plot import plot_search

        plot_search(self, out_dir / "search")
