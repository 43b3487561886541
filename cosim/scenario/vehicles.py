"""The ``vehicles:`` section: each entry expanded by its ``count`` and
formation into ``VehicleSpec``s placed exactly in the scenario's frame,
checked (ids, heights, distances, separation, the class's own rules) with
every problem's line; their random seeds derived from the scenario's."""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.core import limits as lim
from cosim.core.state import VehicleSpec
from cosim.core.units import KT_TO_MPS
from cosim.errors import ConfigError, CosimError
from cosim.scenario.formation import FORMATIONS, formation_offsets
from cosim.scenario.model import Origin
from cosim.scenario.reader import ID, MISSING, P, Problems, Reader, clip, describe, prop_values
from cosim.scenario.yaml_lines import format_path
from cosim.vehicles import DEFAULT_CLASS, ModelChoice, VehicleClass, get_class
from cosim.vehicles.jsb import find_model

ALT_MIN_M, ALT_MAX_M = -500.0, 100_000.0  # every vehicle's resolved height must lie here


#: a vehicle's ``random_seed`` until ``derive_seeds`` derives it from the scenario's
DERIVED_SEED = -1


def derive_seeds(vehicles: list[tuple[VehicleSpec, P]], seed: int
                  ) -> list[tuple[VehicleSpec, P]]:
    """Each vehicle without a ``random_seed`` of its own given one derived from
    the scenario's ``seed`` and its row."""
    import dataclasses

    return [(v if v.random_seed != DERIVED_SEED else dataclasses.replace(
        v, random_seed=int(np.random.SeedSequence([seed, i]).generate_state(1)[0]
                           % (2**31 - 1))), p) for i, (v, p) in enumerate(vehicles)]


def parse_vehicles(ctx: Problems, d: Any, origin: Origin, apath: tuple[str, ...],
              separation: bool = True) -> list[tuple[VehicleSpec, P]]:
    """The vehicle entries, each expanded by its ``count`` and formation (seeds
    to derive: ``derive_seeds``); ``separation``: check the start positions
    are apart too (when nothing else is wrong)."""
    path: P = ("vehicles",)
    if d is MISSING:
        ctx.err((), "missing required key 'vehicles'")
        return []
    if not isinstance(d, list) or not d:
        ctx.err(path, f"expected a non-empty list of vehicles, got {describe(d)}")
        return []
    frame = origin.frame
    ground = origin.ground_alt_m
    out: list[tuple[VehicleSpec, P]] = []
    where_ned: list[np.ndarray] = []  # (count, 3) north, east, height of each entry's vehicles
    seen: dict[str, P] = {}
    planned = 0  # vehicles asked for so far (count included)
    planned_jsbsim = 0  # of them, JSBSim vehicles
    dist = lim.MAX_DISTANCE_M
    for i, vd in enumerate(d):
        vp = path + (i,)
        vclass, model = _vehicle_class(ctx, vd, vp, apath)
        r = Reader(ctx, vd, vp, VEHICLE_KEYS + (vclass.vehicle_keys if vclass else ("trim",
                                                                                        "set")))
        vid = r.string("id", pattern=ID)
        jsbsim = vclass is None or vclass.model_kind == "jsbsim"
        count = r.integer("count", 1, lo=1,
                          hi=lim.MAX_VEHICLES if jsbsim else lim.MAX_ALL_VEHICLES)
        if count is not None:
            planned += count
            planned_jsbsim += count if jsbsim else 0
            if planned_jsbsim > lim.MAX_VEHICLES and jsbsim:
                ctx.err(vp + (("count",) if r.has("count") else ()),
                        f"the scenario would have {planned_jsbsim} or more JSBSim vehicles; "
                        f"at most {lim.MAX_VEHICLES} (each takes about "
                        f"{lim.MIB_PER_VEHICLE} MiB)")
                count = None
            elif planned > lim.MAX_ALL_VEHICLES:
                ctx.err(vp + (("count",) if r.has("count") else ()),
                        f"the scenario would have {planned} or more vehicles; at most "
                        f"{lim.MAX_ALL_VEHICLES} of every kind")
                count = None
        trim = r.boolean("trim", True) if vclass is None or (
            vclass.trims and "trim" in vclass.vehicle_keys) else False
        props = prop_values(ctx, r.d["set"], vp + ("set",)) if r.has("set") else []
        params = vclass.parse_vehicle(r, vp) if vclass else {}
        fixed_seed = r.integer("random_seed", None, lo=0, hi=lim.MAX_VEHICLE_SEED)
        if fixed_seed is not None and count is not None and count > 1:
            ctx.err(vp + ("random_seed",), "random_seed is for a single vehicle; with count, "
                                           "each vehicle's seed derives from the scenario seed")
        ini = Reader(ctx, r.d.get("init"), vp + ("init",),
                      ("lat_deg", "lon_deg", "north_m", "east_m", "alt_msl_m", "alt_agl_m",
                       "heading_deg", "airspeed_kt", "airspeed_mps"))
        if not r.has("init"):
            continue
        pos_geo = ini.has("lat_deg") or ini.has("lon_deg")
        pos_ned = ini.has("north_m") or ini.has("east_m")
        if pos_geo and pos_ned:
            ctx.err(vp + ("init",), "give the position as lat_deg/lon_deg or as north_m/east_m, "
                                    "not both")
        if pos_geo:
            lat, lon = ini.num("lat_deg", lo=-90, hi=90), ini.num("lon_deg", lo=-180, hi=180)
            n0 = e0 = None
        else:
            n0 = ini.num("north_m", 0.0, lo=-dist, hi=dist)
            e0 = ini.num("east_m", 0.0, lo=-dist, hi=dist)
            lat = lon = None
        alt_key = ini.one_of("alt_msl_m", "alt_agl_m")
        alt = None
        on_ground = vclass is not None and vclass.on_ground
        if alt_key is None and on_ground:
            alt = ground  # a ground vehicle: on the ground unless told otherwise
        elif alt_key is None:
            ctx.err(vp + ("init",), "missing the altitude: give alt_msl_m or alt_agl_m")
        else:
            a = ini.num(alt_key, lo=ALT_MIN_M, hi=ALT_MAX_M)
            if a is not None:
                alt = a + (ground if alt_key == "alt_agl_m" else 0.0)
        heading = ini.num("heading_deg", 0.0, lo=-360, hi=360)
        spd_key = ini.one_of("airspeed_kt", "airspeed_mps")
        speed = None
        if spd_key is None and vclass is not None and (on_ground or vclass.hovers):
            speed = 0.0  # at rest
        elif spd_key is None:
            ctx.err(vp + ("init",), "missing the airspeed: give airspeed_kt or airspeed_mps")
        else:
            s = ini.num(spd_key, lo=0, hi=2000)
            if s is not None:
                speed = s * (KT_TO_MPS if spd_key == "airspeed_kt" else 1.0)
                if trim and s == 0:
                    ctx.err(vp + ("init", spd_key), "a trimmed start flies: it needs an "
                                                    "airspeed > 0 (give trim: false for a "
                                                    "vehicle at rest)")
                    speed = None
        offsets = (np.zeros(1), np.zeros(1))
        alt_step = 0.0
        no_formation = count is not None and count > 1 and not r.has("formation")
        if no_formation:
            ctx.err(vp, f"count {count} needs a formation (type: line, grid or circle, "
                        f"with spacing_m)")
        if r.has("formation"):
            fp = vp + ("formation",)
            f = Reader(ctx, r.d.get("formation"), fp,
                        ("type", "spacing_m", "bearing_deg", "columns", "radius_m", "alt_step_m"))
            kind = f.string("type", choices=FORMATIONS)
            spacing = f.num("spacing_m", None if f.has("radius_m") else MISSING, lo=0, hi=dist)
            bearing = f.num("bearing_deg", None, lo=-360, hi=360)
            columns = f.integer("columns", None, lo=1, hi=lim.MAX_ALL_VEHICLES)
            radius = f.num("radius_m", None, lo=0, hi=dist)
            alt_step = f.num("alt_step_m", 0.0, lo=-ALT_MAX_M, hi=ALT_MAX_M) or 0.0
            if kind is not None and (spacing is not None or radius is not None) and count:
                offsets = formation_offsets(kind, count, spacing or 0.0, heading or 0.0,
                                            bearing, columns, radius)
                size = (radius if kind == "circle" and radius is not None else spacing) or 0.0
                if count > 1 and size == 0 and alt_step == 0:
                    ctx.err(fp, f"{count} vehicles would start on one point: give "
                                f"{'radius_m' if kind == 'circle' else 'spacing_m'} > 0 "
                                f"(or alt_step_m)")
                    no_formation = True
        if None in (vid, model, alt, heading, speed, count) or (pos_geo and None in (lat, lon)) \
                or (not pos_geo and None in (n0, e0)) or no_formation:
            continue
        assert model is not None and vid is not None and count is not None
        assert vclass is not None
        assert alt is not None and heading is not None and speed is not None
        dn, de = offsets
        alts = alt + np.arange(count) * alt_step
        alt_p = vp + ("init", alt_key or "alt_msl_m")
        if alts.min() < ALT_MIN_M or alts.max() > ALT_MAX_M:
            ctx.err(alt_p, f"gives altitudes {alts.min():g}..{alts.max():g} m above the "
                           f"ellipsoid (with ground_alt_m and alt_step_m); allowed "
                           f"{ALT_MIN_M:g}..{ALT_MAX_M:g}")
            continue
        agl_min = float(alts.min()) - ground
        if agl_min < 0:
            step = ", with alt_step_m" if count > 1 else ""
            ctx.err(alt_p, f"starts {-agl_min:g} m below the ground (the ground is at "
                           f"{ground:g} m, origin.ground_alt_m{step})")
            continue
        if trim and agl_min < lim.MIN_TRIM_AGL_M:
            ctx.err(alt_p, f"starts {agl_min:g} m above the ground; a trimmed start is in the "
                           f"air: at least {lim.MIN_TRIM_AGL_M:g} m (give trim: false for a "
                           f"vehicle on the ground)")
            continue
        if pos_geo:
            assert lat is not None and lon is not None
            n_base, e_base, _ = frame.geodetic_to_ned(lat, lon, alt)
        else:
            assert n0 is not None and e0 is not None
            n_base, e_base = np.asarray(n0), np.asarray(e0)
        north, east = n_base + dn, e_base + de
        far = float(np.hypot(north, east).max())
        if far > dist:
            ctx.err(vp + ("init",), f"places a vehicle {far / 1000:.0f} km from the origin; at "
                                    f"most {dist / 1000:.0f} km (move origin: closer)")
            continue
        # exact: each vehicle's local north/east are the formation's, at its own height
        lats, lons = frame.place(north, east, alts)
        if count == 1 and pos_geo:
            lats, lons = np.array([lat]), np.array([lon])
        width = len(str(count - 1))
        rows = []
        said: set[str] = set()  # a class's start problems, once an entry
        for j in range(count):
            uid = vid if count == 1 else f"{vid}{j:0{width}d}"
            if len(uid) > lim.MAX_NAME_CHARS:
                ctx.err(vp + ("id",), f"id {clip(uid)!r} (with the number count adds) is "
                                      f"longer than {lim.MAX_NAME_CHARS} characters")
                break
            if uid in seen:
                ctx.err(vp + ("id",), f"duplicate vehicle id {uid!r} (also at "
                                      f"{format_path(seen[uid])}, line {ctx.line(seen[uid])})")
                continue
            seen[uid] = vp
            # derived from the scenario's seed later (``derive_seeds``)
            vseed = fixed_seed if fixed_seed is not None and count == 1 else DERIVED_SEED
            spec = VehicleSpec(
                id=uid, model=model.name, aircraft_dir=model.aircraft_dir,
                model_source=model.source, lat_deg=float(lats[j]), lon_deg=float(lons[j]),
                vehicle_class=vclass.name, class_params=dict(params),
                alt_msl_m=float(alts[j]), heading_deg=float(heading) % 360.0,
                airspeed_mps=float(speed), terrain_alt_m=ground, trim=trim,
                random_seed=vseed, initial_props=tuple(props),
                profile=dict(model.profile or {}))
            for problem in vclass.check_start(spec):
                if problem not in said:
                    said.add(problem)
                    ctx.err(vp + ("init",), problem)
            out.append((spec, vp))
            rows.append(j)
        where_ned.append(np.stack([np.broadcast_to(north, (count,))[rows],
                                   np.broadcast_to(east, (count,))[rows], alts[rows]], axis=1))
    if where_ned and separation and not ctx.problems:
        _check_separation(ctx, out, np.concatenate(where_ned))
    return out


#: vehicles closer than this at the start are reported (stacked on one point)
MIN_SEPARATION_M = 1.0


def _check_separation(ctx: Problems, vehicles: list[tuple[VehicleSpec, P]], ned: np.ndarray
                      ) -> None:
    """Report vehicles that start within ``MIN_SEPARATION_M`` of each other (a
    hash grid of that cell size: each vehicle is compared with its neighbours'
    cells only, so this is linear in the number of vehicles)."""
    cells: dict[tuple[int, int, int], list[int]] = {}
    keys = np.floor(ned / MIN_SEPARATION_M).astype(np.int64)
    reported = 0
    for i, key in enumerate(map(tuple, keys.tolist())):
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for j in cells.get((key[0] + dx, key[1] + dy, key[2] + dz), ()):
                        gap = float(np.linalg.norm(ned[i] - ned[j]))
                        if gap < MIN_SEPARATION_M and reported < 20:
                            reported += 1
                            a, b = vehicles[j][0].id, vehicles[i][0].id
                            ctx.err(vehicles[i][1], f"vehicles {a!r} and {b!r} start "
                                                    f"{gap:.2f} m apart (at least "
                                                    f"{MIN_SEPARATION_M:g} m)")
        cells.setdefault(key, []).append(i)


#: the keys of a vehicle entry every class has (a class adds its ``vehicle_keys``)
VEHICLE_KEYS = ("id", "class", "model", "count", "formation", "init", "random_seed")


def _vehicle_class(ctx: Problems, vd: Any, vp: P, apath: tuple[str, ...]
                   ) -> tuple[VehicleClass | None, ModelChoice | None]:
    """A vehicle entry's class (its ``class:``, else its model profile's, else
    ``jsbsim``) and its model as that class resolves it; problems reported."""
    if not isinstance(vd, dict):
        return None, None  # the entry's reader says what it is
    raw, model_name = vd.get("class"), vd.get("model")
    if raw is not None and not isinstance(raw, str):
        ctx.err(vp + ("class",), f"expected a vehicle class name, got {describe(raw)}")
        return None, None
    if model_name is not None and not isinstance(model_name, str):
        ctx.err(vp + ("model",), f"expected a string, got {describe(model_name)}")
        return None, None
    name = raw
    if name is None:
        if model_name is None:
            ctx.err(vp, "missing required key 'model'")
            return None, None
        try:
            name = str(find_model(model_name, apath).profile.get("class", DEFAULT_CLASS))
        except CosimError as e:
            ctx.err(vp + ("model",), str(e))
            return None, None
    try:
        vclass = get_class(name)
    except ConfigError as e:
        where = vp + ("class",) if raw is not None else vp + ("model",)
        ctx.err(where, str(e) if raw is not None else f"model {model_name!r}: its profile's "
                                                        f"{e}")
        return None, None
    try:
        return vclass, vclass.resolve_model(model_name, apath)
    except CosimError as e:
        ctx.err(vp if model_name is None else vp + ("model",), str(e))
        return vclass, None
