"""MPEG-4 FAPs -> muscle contractions and jaw degrees of freedom (paper §9, §5.2, §6.1).

The mapping is data (``templates/fap_mapping.yaml``). Each *entry* is driven by the
mean value of one or more FAPs (an outer-lip FAP and its inner-lip twin share one
entry, so a file that gives both does not count them twice). The entry's value ``v``
(in the FAP's own FAPU, e.g. MW/1024) goes through three steps:

1. **jaw coupling** (MPEG-4 lip FAPs are absolute displacements of the lip, so the part
   of a lower-lip FAP that the jaw already produces is removed): with
   ``carried = sum_j coupling_j * v_j`` over the coupled FAPs ``j`` (open_jaw), a request
   of the same sign shrinks towards zero, ``v_eff = sign(v) max(|v| - |carried|, 0)``;
   a request of the other sign, or none, is kept (open_jaw alone still parts the lips);
   before that, an entry with a ``muscle_reach`` (the lower lip) may **open the jaw** further
   (:func:`jaw_assisted`): its muscles move the lip at most ``muscle_reach`` FAPU, so a
   request past ``muscle_reach + carried`` raises the coupled FAP (open_jaw) to
   ``(|v| - muscle_reach) / |coupling|``; the jaw then opens to the larger of what the file
   asks and what the lip needs, never their sum;
2. **response curve** (what calibration fits; identity when uncalibrated): a monotone
   piecewise-linear map ``drive = R(v_eff)`` through (0, 0), knots
   ``(requested FAPU, drive FAPU)``, extrapolated linearly with the end slopes;
3. **gains**: ``drive > 0`` contracts the ``positive`` muscles by ``gain * drive``,
   ``drive < 0`` contracts the ``negative`` muscles (antagonists) by ``gain * -drive``
   (``gain`` = contraction per FAPU), and a jaw entry moves its DOF by
   ``gain * drive`` FAPU of displacement at the jaw's lever arm (converted to radians
   for pitch and yaw, to skin length units for protrusion).

A muscle asked for by several entries takes the **largest** request, clipped to
[0, ``max_contraction``] (the muscles map c = 1 to their largest fibre shortening):
several FAPs usually describe one action at several points of the same tissue (the three
upper-lip FAPs 51, 55, 56 and the one orbicularis oris), and each entry is calibrated alone,
so adding them would over-drive the shared muscle. Jaw DOFs add (each has its own FAP) and
are clipped to the mapping's limits. FAP 2 (expression) and FAP 1 (viseme) are expanded
into low-level FAPs with the ``expressions`` and ``visemes`` tables before all this
(:func:`expression_faps`, :func:`viseme_faps`).

FAPs travel as ``(n_frames, 68)`` arrays, column ``k`` = FAP ``k+1``, and FAPU as a
``{"MNS": length, ...}`` dict of skin lengths per FAPU. The standard's tables (FAP count,
FAPU names, expression and viseme codes, their 6-bit maxima) are :mod:`faceforge.mpeg4`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from faceforge.exceptions import TemplateError
from faceforge.mpeg4.expressions import EXPRESSION_CODES, MAX_INTENSITY
from faceforge.mpeg4.tables import FAPU_NAMES, N_FAPS
from faceforge.mpeg4.visemes import MAX_BLEND, VISEME_CODES

JAW_DOFS = ("pitch", "yaw", "protrusion")


@dataclass(frozen=True)
class Measure:
    """What calibration measures for a FAP: an FDP's displacement along ``direction``.

    ``relative_to`` (optional) names a second FDP whose displacement is subtracted
    (e.g. open_jaw: the lower lip relative to the upper lip = how far the lips part).
    """

    fdp: str
    relative_to: str | None = None


@dataclass(frozen=True)
class FapEntry:
    """One row of the mapping (see the module docstring for the arithmetic)."""

    faps: tuple[int, ...]
    name: str
    fapu: str
    positive: dict = field(default_factory=dict)     # muscle -> contraction per FAPU
    negative: dict = field(default_factory=dict)
    jaw: tuple | None = None                          # (dof, gain) in FAPU at the lever
    coupling: dict = field(default_factory=dict)      # FAP number -> ratio (FAPU per FAPU)
    response: np.ndarray | None = None                # (k, 2) knots (requested, drive), sorted
    measure: dict = field(default_factory=dict)       # FAP number -> Measure (calibration)
    muscle_reach: float | None = None                 # FAPU the muscles move the FDP (coupled sense)


@dataclass(frozen=True)
class FapMapping:
    """The whole mapping: entries, jaw limits, and the presets: expressions (low-level FAPs
    at intensity 63) and visemes (low-level FAPs of each mouth shape)."""

    entries: tuple[FapEntry, ...]
    jaw_limits: dict                                  # dof -> (lo, hi); rad, rad, lever fraction
    expressions: dict                                 # name -> (68,) float FAP values
    source: str = "<memory>"
    max_contraction: float = 1.0                      # contractions are clipped to [0, this]
    visemes: dict = field(default_factory=dict)       # name -> (68,) float FAP values

    @property
    def muscles(self) -> tuple[str, ...]:
        """Every muscle name the mapping uses, sorted."""
        names = set()
        for e in self.entries:
            names.update(e.positive)
            names.update(e.negative)
        return tuple(sorted(names))

    def mapped_faps(self) -> np.ndarray:
        """Sorted FAP numbers (int) that drive some entry."""
        return np.array(sorted({f for e in self.entries for f in e.faps}), dtype=np.int64)

    def entry_of(self, fap: int) -> FapEntry:
        for e in self.entries:
            if fap in e.faps:
                return e
        raise KeyError(fap)

    def check_muscles(self, muscle_names) -> None:
        """Raise TemplateError if the mapping names a muscle that ``muscle_names`` lacks."""
        known = set(muscle_names)
        for e in self.entries:
            for m in list(e.positive) + list(e.negative):
                if m not in known:
                    raise TemplateError(
                        f"FAP {e.faps[0]} ({e.name}) names muscle {m!r}, which the muscle map "
                        f"does not have; valid: {sorted(known)}", self.source)


@dataclass(frozen=True)
class JawLevers:
    """Lever arms (skin length units) that turn FAPU displacements into jaw rotations.

    pitch : distance from the pitch axis to the chin FDP 2.1
    yaw : distance from the yaw axis to the chin FDP 2.1
    """

    pitch: float
    yaw: float


# --------------------------------------------------------------------------- loading

def _err(path, msg):
    return TemplateError(msg, path)


def _as_float(value, path, where):
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise _err(path, f"{where}: expected a number, got {value!r}") from None
    if not np.isfinite(x):
        raise _err(path, f"{where}: expected a finite number, got {value!r}")
    return x


def _fap_number(value, path, where):
    try:
        k = int(value)
    except (TypeError, ValueError):
        raise _err(path, f"{where}: expected a FAP number 3..68, got {value!r}") from None
    if not 3 <= k <= N_FAPS:
        raise _err(path, f"{where}: FAP number {k} is not a low-level FAP (3..68)")
    return k


def _muscles(raw, path, where):
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise _err(path, f"{where}: expected a mapping muscle -> gain, got {type(raw).__name__}")
    out = {}
    for m, g in raw.items():
        gain = _as_float(g, path, f"{where}.{m}")
        if gain < 0.0:
            raise _err(path, f"{where}.{m}: gain must be >= 0 (use 'negative:' for antagonists)")
        out[str(m)] = gain
    return out


def _response(raw, path, where):
    if raw is None:
        return None
    try:
        knots = np.asarray(raw, dtype=float).reshape(-1, 2)
    except (TypeError, ValueError):
        raise _err(path, f"{where}: expected a list of [requested, drive] pairs") from None
    if not np.all(np.isfinite(knots)):
        raise _err(path, f"{where}: knots must be finite")
    knots = knots[np.argsort(knots[:, 0], kind="stable")]
    if np.any(np.diff(knots[:, 0]) <= 0.0):
        raise _err(path, f"{where}: requested values must be distinct")
    steps = np.diff(knots[:, 1])
    if not (np.all(steps >= 0.0) or np.all(steps <= 0.0)):
        raise _err(path, f"{where}: drive must be monotone in the requested value")
    return knots


def _entry(raw, path, idx):
    where = f"entries[{idx}]"
    if not isinstance(raw, dict):
        raise _err(path, f"{where}: expected a mapping")
    unknown = set(raw) - {"fap", "name", "fapu", "positive", "negative", "jaw", "coupling",
                          "response", "measure", "muscle_reach"}
    if unknown:
        raise _err(path, f"{where}: unknown keys {sorted(unknown)}")
    faps = raw.get("fap")
    faps = faps if isinstance(faps, list) else [faps]
    faps = tuple(_fap_number(f, path, f"{where}.fap") for f in faps)
    fapu = str(raw.get("fapu", ""))
    if fapu not in FAPU_NAMES:
        raise _err(path, f"{where}: fapu must be one of {list(FAPU_NAMES)}, got {fapu!r}")
    jaw = raw.get("jaw")
    if jaw is not None:
        if not isinstance(jaw, dict) or jaw.get("dof") not in JAW_DOFS:
            raise _err(path, f"{where}.jaw: expected {{dof: one of {list(JAW_DOFS)}, gain: x}}")
        jaw = (jaw["dof"], _as_float(jaw.get("gain", 1.0), path, f"{where}.jaw.gain"))
    coupling = {_fap_number(k, path, f"{where}.coupling"): _as_float(v, path, f"{where}.coupling.{k}")
                for k, v in (raw.get("coupling") or {}).items()}
    measure = {}
    for k, v in (raw.get("measure") or {}).items():
        if not isinstance(v, dict) or "fdp" not in v:
            raise _err(path, f"{where}.measure.{k}: expected {{fdp: 'g.s', relative_to: 'g.s'}}")
        measure[_fap_number(k, path, f"{where}.measure")] = Measure(
            str(v["fdp"]), None if v.get("relative_to") is None else str(v["relative_to"]))
    reach = raw.get("muscle_reach")
    if reach is not None:
        reach = _as_float(reach, path, f"{where}.muscle_reach")
        if reach < 0.0 or not coupling:
            raise _err(path, f"{where}.muscle_reach: expected a number >= 0 on an entry with a coupling")
    return FapEntry(faps=faps, name=str(raw.get("name", f"fap{faps[0]}")), fapu=fapu,
                    positive=_muscles(raw.get("positive"), path, f"{where}.positive"),
                    negative=_muscles(raw.get("negative"), path, f"{where}.negative"),
                    jaw=jaw, coupling=coupling,
                    response=_response(raw.get("response"), path, f"{where}.response"),
                    measure=measure, muscle_reach=reach)


def mapping_from_dict(data: dict, source: str = "<memory>") -> FapMapping:
    """Build and validate a :class:`FapMapping` from parsed YAML ``data``."""
    if not isinstance(data, dict) or "entries" not in data:
        raise _err(source, "expected a mapping with an 'entries' list")
    entries = tuple(_entry(e, source, i) for i, e in enumerate(data["entries"] or []))
    seen = {}
    for e in entries:
        for f in e.faps:
            if f in seen:
                raise _err(source, f"FAP {f} appears in two entries ({seen[f]} and {e.name})")
            seen[f] = e.name
    limits = {}
    for dof in JAW_DOFS:
        lo_hi = (data.get("jaw_limits") or {}).get(dof)
        if lo_hi is None or len(lo_hi) != 2:
            raise _err(source, f"jaw_limits.{dof}: expected [lo, hi]")
        lo, hi = (_as_float(x, source, f"jaw_limits.{dof}") for x in lo_hi)
        if not lo <= 0.0 <= hi:
            raise _err(source, f"jaw_limits.{dof}: expected lo <= 0 <= hi, got [{lo}, {hi}]")
        limits[dof] = (lo, hi)
    expressions = _presets(data, "expressions", EXPRESSION_CODES, source)
    visemes = _presets(data, "visemes", VISEME_CODES, source)
    cmax = _as_float(data.get("max_contraction", 1.0), source, "max_contraction")
    if not 0.0 < cmax <= 1.0:
        raise _err(source, f"max_contraction: expected a number in (0, 1], got {cmax}")
    return FapMapping(entries=entries, jaw_limits=limits, expressions=expressions, source=str(source),
                      max_contraction=cmax, visemes=visemes)


def _presets(data: dict, table: str, ids: dict, source) -> dict:
    """The preset table ``table`` of a mapping (``expressions`` or ``visemes``): name ->
    (68,) low-level FAP values; names outside ``ids`` are an error naming the valid ones."""
    out = {}
    spec_of = data.get(table) or {}
    if not isinstance(spec_of, dict):
        raise _err(source, f"{table}: expected a mapping of name -> {{faps: {{FAP: value}}}}")
    for name, spec in spec_of.items():
        if name not in ids:
            raise _err(source, f"{table}.{name}: unknown {table[:-1]}; valid: {sorted(ids, key=ids.get)}")
        row = np.zeros(N_FAPS)
        for k, v in ((spec or {}).get("faps") or {}).items():
            row[_fap_number(k, source, f"{table}.{name}.faps") - 1] = _as_float(
                v, source, f"{table}.{name}.faps.{k}")
        out[name] = row
    return out


def load_fap_mapping(path) -> FapMapping:
    """Read and validate a FAP mapping YAML file (errors name the file and the entry)."""
    import yaml

    from faceforge.io.stagefiles import yaml_safe_load

    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise TemplateError(f"cannot read FAP mapping: {exc.strerror}", path) from None
    try:
        data = yaml_safe_load(text)
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise TemplateError(f"invalid YAML: {getattr(exc, 'problem', exc)}", path,
                            None if line is None else line + 1) from None
    return mapping_from_dict(data, source=str(path))


def mapping_to_dict(mapping: FapMapping) -> dict:
    """Plain-data form of ``mapping`` (YAML-safe); inverse of :func:`mapping_from_dict`."""
    entries = []
    for e in mapping.entries:
        d = {"fap": list(e.faps) if len(e.faps) > 1 else e.faps[0], "name": e.name, "fapu": e.fapu}
        if e.positive:
            d["positive"] = {k: float(v) for k, v in e.positive.items()}
        if e.negative:
            d["negative"] = {k: float(v) for k, v in e.negative.items()}
        if e.jaw is not None:
            d["jaw"] = {"dof": e.jaw[0], "gain": float(e.jaw[1])}
        if e.coupling:
            d["coupling"] = {int(k): float(v) for k, v in e.coupling.items()}
        if e.measure:
            d["measure"] = {int(k): ({"fdp": m.fdp} if m.relative_to is None else
                                     {"fdp": m.fdp, "relative_to": m.relative_to})
                            for k, m in e.measure.items()}
        if e.muscle_reach is not None:
            d["muscle_reach"] = float(e.muscle_reach)
        if e.response is not None:
            d["response"] = [[float(a), float(b)] for a, b in e.response]
        entries.append(d)
    def presets(table, ids):
        return {name: {"id": ids[name], "faps": {int(k + 1): float(row[k]) for k in np.flatnonzero(row)}}
                for name, row in table.items()}

    out = {"max_contraction": float(mapping.max_contraction), "entries": entries,
           "jaw_limits": {k: [float(v[0]), float(v[1])] for k, v in mapping.jaw_limits.items()},
           "expressions": presets(mapping.expressions, EXPRESSION_CODES)}
    if mapping.visemes:
        out["visemes"] = presets(mapping.visemes, VISEME_CODES)
    return out


def save_fap_mapping(mapping: FapMapping, path, header: str = "") -> None:
    """Write ``mapping`` as YAML (``header`` lines become comments)."""
    import yaml

    text = "".join(f"# {line}\n" for line in header.splitlines())
    text += yaml.safe_dump(mapping_to_dict(mapping), sort_keys=False, default_flow_style=None, width=100)
    Path(path).write_text(text)


def with_entry(mapping: FapMapping, index: int, **changes) -> FapMapping:
    """A copy of ``mapping`` with entry ``index`` replaced by ``replace(entry, **changes)``."""
    entries = list(mapping.entries)
    entries[index] = replace(entries[index], **changes)
    return replace(mapping, entries=tuple(entries))


# --------------------------------------------------------------------------- evaluation

def response_curve(knots: np.ndarray | None, v: np.ndarray) -> np.ndarray:
    """Evaluate the monotone piecewise-linear response through (0, 0).

    Parameters
    ----------
    knots : (k, 2) float or None, sorted (requested FAPU, drive FAPU); None = identity
    v : (n,) float, requested values (FAPU)

    Returns
    -------
    (n,) float drive (FAPU); linear extrapolation with the first/last segment slopes.
    """
    v = np.asarray(v, dtype=float)
    if knots is None or len(knots) == 0:
        return v.copy()
    k = knots
    if not np.any(k[:, 0] == 0.0):
        k = np.vstack([k, [0.0, 0.0]])
        k = k[np.argsort(k[:, 0], kind="stable")]
    x, y = k[:, 0], k[:, 1]
    out = np.interp(v, x, y)
    if len(x) >= 2:
        lo_slope = (y[1] - y[0]) / (x[1] - x[0])
        hi_slope = (y[-1] - y[-2]) / (x[-1] - x[-2])
        out = np.where(v < x[0], y[0] + (v - x[0]) * lo_slope, out)
        out = np.where(v > x[-1], y[-1] + (v - x[-1]) * hi_slope, out)
    return out


def expression_faps(mapping: FapMapping, fap2: np.ndarray) -> np.ndarray:
    """Low-level FAPs (n, 68) for FAP 2 values ``fap2`` (n, >=4).

    Columns: expression_select1, expression_intensity1, expression_select2,
    expression_intensity2 (MPEG-4); each selected expression contributes its table row
    times intensity / 63. Unknown or zero selects contribute nothing.
    """
    fap2 = np.atleast_2d(np.asarray(fap2, dtype=float))
    if fap2.shape[1] < 4:
        raise ValueError(f"fap2 must be (n, >=4), got {fap2.shape}")
    by_id = {EXPRESSION_CODES[n]: row for n, row in mapping.expressions.items()}
    out = np.zeros((len(fap2), N_FAPS))
    for sel_col, int_col in ((0, 1), (2, 3)):
        for i, (sel, inten) in enumerate(fap2[:, [sel_col, int_col]]):
            row = by_id.get(int(round(sel)))
            if row is not None:
                out[i] += row * (inten / MAX_INTENSITY)
    return out


def viseme_weights(fap1: np.ndarray) -> np.ndarray:
    """Weight of each viseme ``(n, 14)`` (column ``k`` = viseme_select ``k + 1``, the order of
    :data:`VISEME_CODES`) for FAP 1 values ``fap1`` (n, >=3).

    Columns: viseme_select1, viseme_select2, viseme_blend (MPEG-4): the mouth shape is
    ``select1 * blend / 63 + select2 * (1 - blend / 63)``, blend clipped to [0, 63]; select 0
    (none) or an unknown code adds nothing (so select1 alone needs blend 63). A viseme in
    both slots gets both weights.
    """
    fap1 = np.atleast_2d(np.asarray(fap1, dtype=float))
    if fap1.shape[1] < 3:
        raise ValueError(f"fap1 must be (n, >=3), got {fap1.shape}")
    share = np.clip(np.nan_to_num(fap1[:, 2]) / MAX_BLEND, 0.0, 1.0)
    out = np.zeros((len(fap1), len(VISEME_CODES)))
    for col, weight in ((0, share), (1, 1.0 - share)):
        code = np.rint(np.nan_to_num(fap1[:, col])).astype(np.int64)
        rows = np.flatnonzero((code >= 1) & (code <= len(VISEME_CODES)))
        np.add.at(out, (rows, code[rows] - 1), weight[rows])
    return out


def viseme_faps(mapping: FapMapping, fap1: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Low-level FAPs (n, 68) for FAP 1 values ``fap1`` (n, >=3): each viseme's table row
    times its :func:`viseme_weights` weight, and the names of the visemes the frames select
    (with a weight) that the mapping's ``visemes`` table lacks."""
    w = viseme_weights(fap1)
    names = sorted(VISEME_CODES, key=VISEME_CODES.get)
    out = np.zeros((len(w), N_FAPS))
    missing = []
    for k, name in enumerate(names):
        if not np.any(w[:, k]):
            continue
        row = mapping.visemes.get(name)
        if row is None:
            missing.append(name)
        else:
            out += np.outer(w[:, k], row)
    return out, missing


def jaw_assisted(mapping: FapMapping, faps: np.ndarray) -> np.ndarray:
    """``faps`` (n, 68) with each coupled FAP (open_jaw) raised to what the lip entries need.

    MPEG-4's lower-lip FAPs are absolute displacements of the lip (the FAP table: open_jaw
    "does not affect mouth opening"; the Xface files give the lower lip 1.1-1.3 x open_jaw).
    An entry with ``muscle_reach`` R (FAPU its own muscles move the FDP at most, in the sense
    the jaw moves it) asking ``v`` past that, with coupling ratio ``k`` to FAP ``j``, needs
    ``(|v| - R) / |k|`` of FAP ``j``; the FAP becomes the largest of its own value and every
    entry's need (a lip lowered alone opens the jaw as a real face does; in a file that opens
    the jaw itself the jaw opens to the larger of the two, not their sum). Returns a copy
    (n, 68); ``faps`` itself when no entry has a reach.
    """
    assisting = [e for e in mapping.entries if e.muscle_reach is not None and e.coupling]
    if not assisting:
        return faps
    out = faps.copy()
    for e in assisting:
        v = faps[:, [f - 1 for f in e.faps]].mean(axis=1)
        for f, ratio in e.coupling.items():
            if ratio == 0.0:
                continue
            lip = np.where(np.sign(v) == np.sign(ratio), np.abs(v), 0.0)
            need = np.maximum(lip - e.muscle_reach, 0.0) / abs(ratio)
            out[:, f - 1] = np.maximum(out[:, f - 1], need)
    return out


def entry_drive(mapping: FapMapping, faps: np.ndarray) -> np.ndarray:
    """Drive (n, n_entries) FAPU of every entry for low-level FAP frames ``faps`` (n, 68),
    after the jaw's help to the lower lip (:func:`jaw_assisted`)."""
    faps = np.atleast_2d(np.asarray(faps, dtype=float))
    if faps.shape[1] != N_FAPS:
        raise ValueError(f"faps must be (n, {N_FAPS}), got {faps.shape}")
    faps = jaw_assisted(mapping, faps)
    drive = np.zeros((len(faps), len(mapping.entries)))
    for j, e in enumerate(mapping.entries):
        v = faps[:, [f - 1 for f in e.faps]].mean(axis=1)
        if e.coupling:
            carried = sum(ratio * faps[:, f - 1] for f, ratio in e.coupling.items())
            same = np.sign(v) * np.sign(carried) > 0.0
            v = np.where(same, np.sign(v) * np.maximum(np.abs(v) - np.abs(carried), 0.0), v)
        drive[:, j] = response_curve(e.response, v)
    return drive


def fap_controls(mapping: FapMapping, faps: np.ndarray, muscle_names, fapu: dict,
                 levers: JawLevers) -> tuple[np.ndarray, np.ndarray]:
    """Muscle contractions and jaw DOFs for FAP frames.

    Parameters
    ----------
    faps : (n, 68) float, low-level FAP values (column k = FAP k+1; columns 0, 1 ignored)
    muscle_names : sequence of m str, the column order of the contractions
    fapu : dict FAPU name -> skin length per FAPU (e.g. MNS0 / 1024); AU in radians
    levers : jaw lever arms (skin length units)

    Returns
    -------
    contractions : (n, m) float in [0, max_contraction], per muscle the largest request of any entry
    jaw : (n, 3) float, (pitch rad, yaw rad, protrusion skin units), within the limits
    """
    names = list(muscle_names)
    col = {n: i for i, n in enumerate(names)}
    mapping.check_muscles(names)
    drive = entry_drive(mapping, faps)
    n = len(drive)
    c = np.zeros((n, len(names)))
    jaw = np.zeros((n, 3))
    for j, e in enumerate(mapping.entries):
        d = drive[:, j]
        pos, neg = np.maximum(d, 0.0), np.maximum(-d, 0.0)
        for m, g in e.positive.items():
            c[:, col[m]] = np.maximum(c[:, col[m]], g * pos)
        for m, g in e.negative.items():
            c[:, col[m]] = np.maximum(c[:, col[m]], g * neg)
        if e.jaw is not None:
            dof, gain = e.jaw
            length = gain * d * float(fapu[e.fapu])
            if dof == "pitch":
                jaw[:, 0] += np.arctan2(length, levers.pitch)
            elif dof == "yaw":
                jaw[:, 1] += np.arctan2(length, levers.yaw)
            else:
                jaw[:, 2] += length
    for k, dof in enumerate(JAW_DOFS):
        lo, hi = mapping.jaw_limits[dof]
        scale = levers.pitch if dof == "protrusion" else 1.0
        jaw[:, k] = np.clip(jaw[:, k], lo * scale, hi * scale)
    return np.clip(c, 0.0, mapping.max_contraction), jaw
