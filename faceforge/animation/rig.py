"""The rig of a fitted and bound head (paper §9): assembled from the fit and bind arrays.

:class:`BoundHead` loads ``fit.npz`` and ``bind.npz``, rebuilds the layered muscles on the
fitted skull (§6, :func:`muscle_system`), the skin layer on its anchors (§8) and the guards,
and exposes them as a :class:`faceforge.animation.playback.Rig` of three steps:

* skull: :class:`JawDrive` (jaw DOFs -> the mandible's transform, held poses reuse it);
* muscles: :class:`MuscleDrive` (contractions in :attr:`BoundHead.controls` order);
* skin: :class:`faceforge.animation.guards.alternate.GuardedSkinStep`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

#: FDPs on the lower lip (inner and outer contour), located on the lower side of a cut lip line
LOWER_LIP_FDPS = ("2.3", "2.8", "2.9", "8.2", "8.7", "8.8")
UPPER_LIP_FDPS = ("2.2", "2.6", "2.7", "8.1", "8.5", "8.6")


class JawDrive:
    """The rig's skull step: jaw DOFs (3,) -> the mandible's transform, set on the system.

    A held pose repeats its DOFs: the transform is recomputed only when their bits change
    (``-0.0`` is not ``0.0`` here). :attr:`transform` is the last one (None before the first
    frame); the step returns None (the muscles read the bones from the system)."""

    def __init__(self, skull, system):
        self.skull, self.system = skull, system
        self._key = None
        self.transform = None

    def __call__(self, jaw):
        key = np.asarray(jaw, dtype=float).tobytes()
        if key != self._key:
            self._key, self.transform = key, self.skull.jaw_transform(*jaw)
        self.system.set_jaw(self.transform)  # returns at once when the mandible is already there


class RigidParts:
    """The rig's ``parts`` step: the mesh's pieces that ride a bone (bind.npz ``parts``,
    :func:`faceforge.skin.parts.rigid_parts`) put rigidly where it is, in place on a weighted
    frame (n, 3): those on the cranium at rest (head frame), those on the mandible by the jaw's
    last transform (:attr:`JawDrive.transform`; at rest before the first frame)."""

    def __init__(self, rest, parts, jaw: JawDrive):
        from faceforge.skin.parts import ON_CRANIUM, ON_MANDIBLE

        parts = np.asarray(parts)
        self.cranium = np.flatnonzero(parts == ON_CRANIUM)
        self.mandible = np.flatnonzero(parts == ON_MANDIBLE)
        self.rest_cranium = np.asarray(rest, dtype=float)[self.cranium]
        self.rest_mandible = np.asarray(rest, dtype=float)[self.mandible]
        self.jaw = jaw

    def __call__(self, frame):
        frame[self.cranium] = self.rest_cranium
        t = self.jaw.transform
        frame[self.mandible] = self.rest_mandible if t is None else self.rest_mandible @ t[:3, :3].T + t[:3, 3]


class MuscleDrive:
    """The rig's muscle step: contractions (m,) in the system's ``controls`` order, passed on as
    they are (each layer reads its muscles' columns)."""

    def __init__(self, system):
        self.system = system

    def __call__(self, c, _bones, dt: float):
        self.system.step(c, None, dt)


class BoundHead:
    """Everything animate and calibrate need, loaded from the fit and bind stages.

    Attributes
    ----------
    rig : faceforge.animation.playback.Rig (working skin)
    muscle_names : tuple of str, the muscles
    controls : tuple of str, column order of the contractions: the muscles, then the
        sphincter's protrusion drive (``MusculoskeletalSystem.controls``)
    skull : faceforge.anatomy.skull.Skull (fitted; jaw_transform); levers : JawLevers
    fapu : faceforge.mpeg4.Fapu
    rest : (n, 3) working skin at rest; faces : (m, 3) working faces
    user_index : (n_user,) int, working vertex of each of the user's vertices
    user_rotation : (3, 3) head space = the user's frame ``@ user_rotation.T`` (fit.npz)
    fdp_vertex : dict FDP -> working vertex index
    landmarks : dict FDP -> (3,) position on the neutral skin (head frame)
    cranium, mandible : (vertices, faces) at rest
    system : faceforge.anatomy.layers.MusculoskeletalSystem; skin : SkinSimulation
    guard : faceforge.animation.guards.skull.SkullGuard; collision : BoneCollision or None
    orientation : faceforge.animation.guards.orientation.OrientationGuard, or None when
        ``animate.orientation_guard.rounds`` is 0; after each skin step it alternates with
        the skull guard, and it is the rig's ``finish`` on each weighted frame
    parts : (n,) int8, the pieces that ride a bone rigidly (eyeballs, teeth; bind.npz, 0 = skin),
        put on it by the rig's ``parts`` step (:class:`RigidParts`)
    symmetric : bool, True on a rig symmetric by construction (fit.npz's mirror plane, every
        skin vertex with an exact mirror partner; set where the skin is loaded): calibration
        then probes one side of each left/right pair (``animation.calibrate_mirror``)

    ``cache`` (a folder, or None): where the built muscles are kept between commands
    (:func:`built_muscles`; the stages pass ``<workdir>/cache``).
    """

    def __init__(self, fit_dir: Path, bind_dir: Path, config, log=lambda m: None, cache: Path | None = None):
        from faceforge.animation.playback import Rig
        from faceforge.io.stagefiles import load_npz
        from faceforge.pbd import SolverSettings

        fit = load_npz(Path(fit_dir) / "fit.npz")
        bind = load_npz(Path(bind_dir) / "bind.npz")
        self._load_head(fit, bind, Path(fit_dir))
        self.jaw_glide = self._glide_ratio(config)
        if self.jaw_glide > 0:   # the condyles slide as the mouth opens
            from dataclasses import replace

            from faceforge.anatomy.skull import condylar_glide

            jaw = self.skull.jaw
            glide = condylar_glide(jaw.protrusion_dir, jaw.pitch_dir, self.levers.pitch,
                                   self.jaw_glide, config.get("animate.jaw_glide_slope"))
            self.skull = replace(self.skull, jaw=replace(jaw, glide=glide))
        settings = SolverSettings.from_config(config.get("solver"))
        self.system = system = muscle_system(fit, self.cranium, self.mandible, settings, config, log, cache=cache)
        self.muscle_names = tuple(system.muscles)
        self.controls = system.controls
        self.skin = self._skin(bind, Path(bind_dir), settings, config, fit)
        self._guards(config, cache)
        jaw = JawDrive(self.skull, system)
        skin_step = self._skin_step(jaw, int(config.get("animate.orientation_guard.rounds")),
                                    bool(config.get("animate.orientation_guard.fold_progress")))

        def reset():
            system.reset()
            self.skin.reset()

        #: (n,) int8, the pieces that ride a bone (:func:`faceforge.skin.parts.rigid_parts`; all 0
        #: on a head bound before they were told apart)
        self.parts = np.asarray(bind.get("parts", np.zeros(len(self.rest), np.int8)))
        self._inside_at_rest = None   # inside_at_rest(), once asked
        self.rig = Rig(skull=jaw, muscles=MuscleDrive(system), skin=skin_step, rest=self.rest,
                       influence=np.asarray(bind["influence"], dtype=float), reset=reset,
                       finish=None if self.orientation is None else self.orientation.apply,
                       blend=self._blend_limit(bind),
                       parts=RigidParts(self.rest, self.parts, jaw) if self.parts.any() else None)

    def _glide_ratio(self, config) -> float:
        """``animate.jaw_glide``, or with ``animate.chin_path`` > 0 the fraction at which this
        head's chin (FDP 2.1) follows that path (:func:`faceforge.anatomy.skull.chin_path_ratio`)."""
        back_per_down = float(config.get("animate.chin_path"))
        if back_per_down <= 0 or "2.1" not in self.landmarks:
            return float(config.get("animate.jaw_glide"))
        from faceforge.anatomy.skull import chin_path_ratio

        jaw = self.skull.jaw
        return chin_path_ratio(self.landmarks["2.1"], jaw.pitch_point, jaw.pitch_dir, jaw.protrusion_dir,
                               config.get("animate.jaw_glide_slope"), back_per_down)

    def _load_head(self, fit: dict, bind: dict, fit_dir: Path) -> None:
        """The skin, bones, jaw axes, landmarks, FAPU and jaw levers of fit.npz and bind.npz."""
        from faceforge.anatomy.skull import JawAxes, Skull
        from faceforge.animation.fap_mapping import JawLevers
        from faceforge.exceptions import StageError
        from faceforge.mpeg4 import fapu_from_landmarks

        self.cranium = (fit["cranium_vertices"], fit["cranium_faces"])
        self.mandible = (fit["mandible_vertices"], fit["mandible_faces"])
        self.rest = np.asarray(bind["vertices"], dtype=float)
        self.faces = np.asarray(bind["faces"], dtype=np.int64)
        n_internal = int(bind["n_user"])
        u2i = fit["skin_user_to_internal"] if "skin_user_to_internal" in fit else np.arange(n_internal)
        self.user_index = np.asarray(u2i, dtype=np.int64)
        from faceforge.geometry.embed import NPZ_PREFIX, Embedding

        #: a dense skin's vertices on this proxy (fit.simulation_vertices), or None: the user's own mesh
        self.embedding = Embedding.from_arrays(fit, NPZ_PREFIX)
        #: (t, 3) the user's triangles (user vertex ids) when :attr:`embedding` is set
        self.user_faces = np.asarray(fit["skin_user_faces"], np.int64) if self.embedding is not None else None
        if self.embedding is not None:   # the proxy's triangles on the working mesh (bind's lip cut)
            from faceforge.geometry.embed import embed_off, working_corners

            self.embedding = embed_off(self.embedding, fit["skin_vertices"], fit["skin_faces"],
                                       bind.get("removed_faces", np.zeros(0, np.int64)), self.user_index)

            self._carry_faces = working_corners(fit["skin_faces"], self.faces, len(fit["skin_vertices"]),
                                                bind.get("duplicate_source", np.zeros(0, np.int64)))
        self.user_rotation = np.asarray(fit["user_rotation"], dtype=float) if "user_rotation" in fit else np.eye(3)
        try:
            axes = JawAxes(*(np.asarray(fit[f"jaw_{k}"], dtype=float) for k in (
                "pitch_point", "pitch_direction", "yaw_point", "yaw_direction",
                "protrusion_direction")), limits={}, condyles=np.zeros((2, 3)))
        except KeyError as exc:
            raise StageError(f"fit.npz lacks the jaw axes ({exc.args[0]}); rerun `faceforge fit`",
                             fit_dir / "fit.npz") from None
        self.skull = Skull(self.cranium, self.mandible, {}, {}, axes)
        self.landmarks = skin_lm = {str(k): p for k, p in zip(fit["skin_landmark_ids"],
                                                              fit["skin_landmark_positions"])}
        given = {str(k): p for k, p in zip(fit.get("given_landmark_ids", ()), fit.get("given_landmark_positions", ()))}
        self.fapu = fapu_from_landmarks({**skin_lm, **given}, fit_dir / "fit.npz")   # FAPU: as given
        self.fdp_vertex = fdp_vertices(skin_lm, self.rest, bind.get("lip_sides"))
        chin = skin_lm.get("2.1", self.rest[self.fdp_vertex.get("2.1", 0)])
        self.levers = JawLevers(lever_arm(chin, axes.pitch_point, axes.pitch_dir),
                                lever_arm(chin, axes.yaw_point, axes.yaw_dir))

    def _skin(self, bind: dict, bind_dir: Path, settings, config, fit: dict):
        """The §8 skin layer on the binding's anchors, checked against the rebuilt system; on a
        symmetric rig (fit.npz's mirror, every skin vertex with a partner) its solver colours
        mirror twins alike (:func:`faceforge.pbd.colouring.mirror_colouring`)."""
        from faceforge.geometry.mirror import Mirror
        from faceforge.exceptions import StageError
        from faceforge.skin.binding import Binding
        from faceforge.skin.layer import SkinSimulation, SkinStiffness

        system = self.system
        binding = Binding.from_arrays(bind)
        missing = [n for n in binding.body_names if n not in system.names]
        if missing:
            raise StageError(f"bind.npz binds the skin to {missing}, which the fitted head lacks; "
                             "rerun `faceforge bind`", bind_dir / "bind.npz")
        for b, name in enumerate(binding.body_names):
            ids = binding.face_ids[binding.body == b]
            if len(ids) and ids.max() >= len(system.faces(name)):
                raise StageError(f"bind.npz binds the skin to faces of {name!r} that the fitted head does "
                                 "not have (the muscle map changed?); rerun `faceforge bind`",
                                 bind_dir / "bind.npz")
        # anchors on the system's own rest bodies (the rebuilt muscles may differ from the meshes
        # bind saw by a projection): then the rest pose is an exact fixed point
        binding = replace(binding, points=binding.targets([system.surface(n) for n in binding.body_names]))
        mirror = Mirror.from_arrays(fit)
        partner = None if mirror is None else mirror.exact_partners(self.rest)
        #: True on a rig symmetric by construction whose skin has an exact mirror partner per vertex
        self.symmetric = partner is not None
        self._folds = self._fold_limit(bind, config)
        from faceforge.skin.brow import lid_hold
        from faceforge.skin.cheek import cheek_tether

        tether = cheek_tether(binding, config.get("bind.cheek_muscles"), config.get("skin.cheek_tether"))
        lids, held = lid_hold(binding, self.rest, self.landmarks, float(config.get("skin.lid_hold")))
        if lids is not None:   # skin.lid_hold: the upper lids' skin stays where the lids put it
            tether = lids if tether is None else np.where(held, lids, tether)
        return SkinSimulation(self.rest, self.faces, binding, SkinStiffness.from_config(config),
                              settings, carried=carried_anchors(binding, config.get("skin.carry")) | held,
                              mirror=partner, join=bool(config.get("skin.join_insertions")),
                              tether=tether,
                              carry_radius=carry_radius(config, self.landmarks),
                              fold_limit=self._folds, lip_contact=self._lip_contact(bind, config),
                              sink=self._lid_sink(binding, held, config) if lids is not None else None)

    def _lid_sink(self, binding, held, config):
        """``skin.lid_hold_sink``: the held lid rows, the share, up (+Y) and each row's way toward
        the nose (:func:`faceforge.skin.brow.toward_nose`) for :class:`SkinSimulation`'s ``sink``."""
        from faceforge.skin.brow import toward_nose

        rows = np.flatnonzero(held)
        medial = toward_nose(self.rest, self.landmarks)[np.asarray(binding.vertex_ids)[rows]]
        return rows, float(config.get("skin.lid_hold_sink") or 0.0), (0.0, 1.0, 0.0), medial

    def _lip_contact(self, bind: dict, config):
        """The lips' one-sided contact (``skin.lip_contact_mm``, the radius in mm within which a lip's
        vertex meets the other lip at rest: :func:`faceforge.skin.lip_contact.lip_contacts`); None
        when it is 0 or the head has no lips."""
        from faceforge.anatomy.tissue import units_per_mm
        from faceforge.skin.lip_contact import lip_contacts

        mm = float(config.get("skin.lip_contact_mm") or 0.0)
        if mm <= 0.0:
            return None
        try:
            radius = mm * units_per_mm(self.landmarks)
        except KeyError:
            return None
        return lip_contacts(self.rest, self.faces, bind.get("lip_sides"), radius)

    def _fold_limit(self, bind: dict, config):
        """(quads (m, 4), limits (m,) radians) the skin may not bend past: ``skin.fold_deg`` on
        the quads flat at rest (not on a proxy head unless ``skin.proxy_fold_limit``),
        ``skin.commissure_fold_deg`` on the lips' corners (:func:`faceforge.skin.fold_limit.fold_limits`);
        None when both are 0."""
        from faceforge.skin.fold_limit import fold_limits
        from faceforge.skin.lip_contact import commissure_quads

        corner = float(config.get("skin.commissure_fold_deg") or 0.0)
        quads = commissure_quads(self.rest, self.faces, bind.get("lip_sides"), self.landmarks) \
            if corner > 0 else None
        fold = float(config.get("skin.fold_deg") or 0.0)
        if self.embedding is not None and not config.get("skin.proxy_fold_limit"):   # a proxy: corners only
            fold = 0.0
        return fold_limits(self.rest, self.faces, fold, quads, corner)

    def _blend_limit(self, bind: dict):
        """The influence blend kept within the skin's fold limit
        (:class:`faceforge.skin.fold_limit.BlendLimit`, on the quads and limits of
        :meth:`_fold_limit`), or None without a fold limit."""
        from faceforge.skin.fold_limit import BlendLimit

        if self._folds is None:
            return None
        blend = BlendLimit(self.rest, np.asarray(bind["influence"], dtype=float), *self._folds)
        return blend if len(blend.quads) else None

    def _guards(self, config, cache=None) -> None:
        """:attr:`guard`, :attr:`collision` and :attr:`orientation` as the config sets them; the skull
        guard and the bone collision read back from ``cache`` (a folder) when built there before on
        the same skin, bones and settings (:func:`faceforge.anatomy.muscles.build_cache.cached`)."""
        from faceforge.anatomy.muscles.build_cache import cached
        from faceforge.animation.guards.bone_collision import BoneCollision
        from faceforge.animation.guards.orientation import OrientationGuard
        from faceforge.animation.guards.skull import SkullGuard

        bones = {"cranium": self.cranium, "mandible": self.mandible}
        head = (("rest", self.rest), *((f"{n}_{i}", np.asarray(b[i])) for n, b in bones.items() for i in (0, 1)))
        diag = float(np.linalg.norm(np.ptp(self.rest, axis=0)))
        keep = float(config.get("animate.skull_guard.keep"))
        reach = float(config.get("animate.skull_guard.reach")) * diag
        self.guard = cached(cache, "skullguard", (*head, ("reach", reach), ("keep", keep)),
                            lambda: SkullGuard(self.rest, bones, reach=reach, keep=keep))
        reach = float(config.get("animate.skull_guard.collision_reach")) * diag
        if reach > 0:
            sweeps = {"mandible": jaw_sweep(self.skull, self.mandible[0], reach)}
            keep = float(config.get("animate.skull_guard.collision_keep"))
            self.collision = cached(cache, "collision", (*head, ("reach", reach), ("keep", keep),
                                                         ("sweeps", sweeps["mandible"])),
                                    lambda: BoneCollision(self.rest, bones, reach=reach, keep=keep, sweeps=sweeps))
        else:
            self.collision = None
        rounds = int(config.get("animate.orientation_guard.rounds"))
        # a projection moves a vertex at most its triangle's longest rest edge (MakeHuman's pride.fap on a
        # levelled risorius threw a lid-corner vertex 0.74 units for a frame: docs/notes/ris23.md)
        self.orientation = OrientationGuard(
            self.rest, self.faces, min_area=float(config.get("animate.orientation_guard.min_area")), reach=1.0) \
            if rounds > 0 else None

    def _skin_step(self, jaw: JawDrive, rounds: int, progress: bool = False):
        from faceforge.animation.guards.alternate import GuardedSkinStep

        return GuardedSkinStep(self.system, self.skin, self.guard, self.orientation, self.collision,
                               rounds, jaw, progress)

    def bone_heights(self) -> tuple[float, float]:
        """(lowest, highest) height (+Y) of the bones at rest (cranium and mandible)."""
        y = np.concatenate([self.cranium[0][:, 1], self.mandible[0][:, 1]])
        return float(y.min()), float(y.max())

    def eyelids(self, config):
        """The lids of this head's eyes (:class:`faceforge.animation.eyelids.Eyelids`) as the
        config sets them (``animate.eyelids``, ``.eyelid_reach``, ``.eyelid_depth``, ``.eyelid_fold_deg``,
        ``.eyelid_jaw_hold``, ``.eyelid_relative``); None when
        ``animate.eyelids`` is off."""
        from faceforge.animation.eyelids import Eyelids

        if not config.get("animate.eyelids"):
            return None
        return Eyelids(self.rest, self.faces, self.landmarks, self.fapu.unit("IRISD"),
                       config.get("animate.eyelid_reach"), config.get("animate.eyelid_depth"),
                       float(config.get("animate.eyelid_fold_deg") or 0.0),
                       float(config.get("animate.eyelid_jaw_hold") or 0.0), rigid=self.parts != 0,
                       relative=bool(config.get("animate.eyelid_relative")))

    def inside_at_rest(self) -> np.ndarray:
        """(n,) bool: the working vertices the bone checks do not count (``inside_at_rest`` of
        :func:`faceforge.animation.checks.check_animation`): those inside the bones at rest, and the
        pieces that ride a bone (:attr:`parts`: an eyeball turning in its orbit, teeth moving with
        the jaw are not skin). Computed once."""
        if self._inside_at_rest is None:
            from faceforge.animation.checks import inside_bones

            self._inside_at_rest = inside_bones(self.rest, self.skull_at(np.zeros(3))) | (self.parts != 0)
        return self._inside_at_rest

    def skull_at(self, jaw_dofs):
        """[(vertices, faces)] of cranium and mandible for jaw DOFs (3,)."""
        t = self.skull.jaw_transform(*jaw_dofs)
        v, f = self.mandible
        return [self.cranium, (v @ t[:3, :3].T + t[:3, 3], f)]

    def carried(self, frames):
        """(F, n_working, 3) -> (F, n_user, 3) in the user's vertex order, head space: a proxy's
        frames carried to the dense mesh (:attr:`embedding`), else the user's vertices picked."""
        if self.embedding is None:
            return frames[:, self.user_index]
        from faceforge.geometry.embed import carry

        frames = np.asarray(frames)
        return carry(frames, self._carry_faces, self.embedding).astype(frames.dtype, copy=False)

    def carried_check(self):
        """A :class:`~faceforge.animation.checks.CarriedInversions` of the user's mesh on this
        proxy (fed :meth:`carried` frames), or None without a proxy."""
        if self.embedding is None:
            return None
        from faceforge.animation.checks import CarriedInversions

        return CarriedInversions(self.carried(self.rest[None])[0], self.user_faces)

    def check_carried(self, report, frames):
        """``report`` (a FrameReport of working ``frames (k, n, 3)``) with the carried mesh's
        turned triangles (:attr:`FrameReport.carried`) on a proxy; unchanged without one."""
        check = self.carried_check()
        if check is not None:
            check.add(self.carried(np.asarray(frames)))
            report.carried = check.as_dict()
        return report

    def to_user(self, frames):
        """(F, n_working, 3) -> (F, n_user, 3) in the user's vertex order and frame."""
        return self.user_frame(self.carried(frames))

    def user_frame(self, carried):
        """:meth:`carried` frames ``(F, n_user, 3)`` (head space) in the user's frame."""
        return carried if np.array_equal(self.user_rotation, np.eye(3)) else carried @ self.user_rotation


#: the jaw's range the bone collision guards against (rad): the template's limits (jaw.yaml),
#: which the fitted skull does not carry; 0.4 rad parts the incisors ~3.5 cm
JAW_SWEEP_PITCH, JAW_SWEEP_YAW = 0.4, 0.1


def jaw_sweep(skull, mandible_vertices, reach: float) -> np.ndarray:
    """(p, 4, 4) mandible transforms over its opening (0 .. JAW_SWEEP_PITCH rad, with the glide)
    and side shift (+-JAW_SWEEP_YAW at half the opening), spaced so that no vertex of the
    mandible (``(v, 3)``, skin units) moves more than ``reach / 2`` between neighbours (at most 64
    openings; both side shifts keep a symmetric rig's guard symmetric): skin within
    ``reach`` of any of them is guarded by the bone collision (it may meet the moving jaw)."""
    j = skull.jaw
    v = np.asarray(mandible_vertices, dtype=float)
    radius = float(np.max(np.linalg.norm(np.cross(v - j.pitch_point, j.pitch_dir), axis=1)))
    per_rad = radius / float(np.linalg.norm(j.pitch_dir)) + (
        float(np.linalg.norm(j.glide)) if j.glide is not None else 0.0)
    n = max(2, int(np.ceil(JAW_SWEEP_PITCH * per_rad / max(0.5 * reach, 1e-12))) + 1)
    poses = [(p, 0.0) for p in np.linspace(0.0, JAW_SWEEP_PITCH, min(n, 64))[1:]]
    poses += [(0.5 * JAW_SWEEP_PITCH, s * JAW_SWEEP_YAW) for s in (-1.0, 1.0)]
    return np.stack([skull.jaw_transform(p, y, 0.0) for p, y in poses])


def carry_radius(config, landmarks) -> float:
    """``skin.carry_radius_mm`` in skin units (scaled by ES0, ``anatomy.tissue.units_per_mm``);
    0 without the eye FDPs that give ES0 (:mod:`faceforge.skin.carry_smooth`)."""
    from faceforge.anatomy.tissue import units_per_mm

    mm = float(config.get("skin.carry_radius_mm"))
    try:
        return mm * units_per_mm(landmarks) if mm > 0 else 0.0
    except KeyError:
        return 0.0


def carried_anchors(binding, carry: str):
    """(k,) bool: the anchors that carry their skin vertex (``skin.carry``: muscles | all | none;
    :class:`faceforge.skin.layer.SkinSimulation`)."""
    bone = binding.on_bone()
    return {"muscles": ~bone, "all": np.ones(len(bone), bool), "none": np.zeros(len(bone), bool)}[carry]


def lever_arm(point, axis_point, axis_dir) -> float:
    """Distance from ``point`` (3,) to the line through ``axis_point`` along ``axis_dir``."""
    d = np.asarray(axis_dir, dtype=float) / np.linalg.norm(axis_dir)
    r = np.asarray(point, dtype=float) - axis_point
    return float(np.linalg.norm(r - (r @ d) * d))


def fdp_vertices(landmarks: dict, rest, lip_sides) -> dict:
    """FDP -> nearest working vertex.

    Where the lip line was cut by duplicating a shared ring, an upper and a lower vertex sit
    at the same place: lower-lip FDPs then take the lower copy (``lip_sides < 0``) and
    upper-lip FDPs the upper one (``lip_sides > 0``), whenever such a vertex is as near as the
    nearest vertex overall.
    """
    sides = np.zeros(len(rest), dtype=np.int8) if lip_sides is None else np.asarray(lip_sides)
    out = {}
    for fdp, p in landmarks.items():
        d = np.linalg.norm(rest - np.asarray(p, dtype=float), axis=1)
        want = -1 if fdp in LOWER_LIP_FDPS else 1 if fdp in UPPER_LIP_FDPS else 0
        if want and np.any(sides == want):
            side = np.where(sides == want, d, np.inf)
            if side.min() <= d.min() * (1.0 + 1e-9) + 1e-12:
                d = side
        out[fdp] = int(np.argmin(d))
    return out


def muscle_system(fit, cranium, mandible, settings, config, log, cache=None):
    """The layered muscles of the fitted head (§6), rebuilt from fit.npz.

    The muscle map's specs (``template.muscle_map`` on ``template.skull``) get the fitted
    points the fit stage stored (``muscle_map_points``, in ``MuscleSpec.points()`` order) and
    are built on the fitted skull (Eq. 5 thickness from its diagonal), deepest layer first;
    on a symmetric rig (fit.npz has ``mirror_point`` / ``mirror_normal``) each right muscle is
    built as the mirror image of its left twin. Without muscles in fit.npz the system is the
    skull alone. ``cache`` (a folder, or None): the built muscles are kept there and read back
    when everything the build reads is unchanged (:func:`built_muscles`).
    """
    from faceforge.anatomy.layers import MusculoskeletalSystem
    from faceforge.geometry.mirror import Mirror

    if "muscle_map_names" not in fit or not len(fit["muscle_map_names"]):
        log("fit.npz has no muscles: animating the skull alone")
        return MusculoskeletalSystem.from_parts(cranium, mandible, [], settings)
    muscles = built_muscles(fit, cranium, mandible, config, cache)
    settings = replace(settings, damping=float(config.get("muscle.damping")))
    system = MusculoskeletalSystem.from_parts(cranium, mandible, muscles, settings, Mirror.from_arrays(fit))
    from faceforge.anatomy.muscles.modiolus import attach_lip_ties, attach_modiolus

    attach_modiolus(system, muscles=tuple(config.get("muscle.sphincter.modiolus.muscles")),
                    radius=float(config.get("muscle.sphincter.modiolus.radius")),
                    ramp=float(config.get("muscle.sphincter.modiolus.ramp")))
    attach_lip_ties(system, lower=tuple(config.get("muscle.sphincter.lip_ties.lower")),
                    upper=tuple(config.get("muscle.sphincter.lip_ties.upper")),
                    radius=float(config.get("muscle.sphincter.lip_ties.radius")),
                    ramp=float(config.get("muscle.sphincter.lip_ties.ramp")))
    return system


#: the muscle build's config keys (:func:`built_muscles`)
BUILD_KEYS = ("template.muscle_map", "template.skull", "muscle.linear.stiffness", "muscle.sphincter.stiffness",
              "muscle.sphincter.carry_inner", "muscle.sphincter.protrusion", "muscle.sphincter.inner_on_bone",
              "muscle.sphincter.closure_centre", "muscle.sphincter.closure_vertical",
              "muscle.sphincter.eversion_up", "muscle.sphincter.bulge")


def built_muscles(fit, cranium, mandible, config, cache=None) -> list:
    """The fitted head's ``[Muscle]`` (:func:`faceforge.anatomy.muscles.build.build_muscles_on`),
    built, or read back from ``cache`` (a folder) where a build of the same fit arrays, template
    files, config keys (:data:`BUILD_KEYS`) and build code was kept
    (:mod:`faceforge.anatomy.muscles.build_cache`); a fresh build is kept there."""
    from faceforge.anatomy.muscles.build_cache import cached
    from faceforge.io.templates import resolve_template_path

    mirror = tuple((k, np.asarray(fit[k])) for k in ("mirror_point", "mirror_normal") if k in fit)
    return cached(cache, "muscles", (
        *((k, np.asarray(fit[k])) for k in ("muscle_map_names", "muscle_map_start", "muscle_map_points")),
        ("cranium", np.asarray(cranium[0])), ("cranium_faces", np.asarray(cranium[1])),
        ("mandible", np.asarray(mandible[0])), ("mandible_faces", np.asarray(mandible[1])), *mirror,
        ("muscle_map_file", Path(resolve_template_path(config.get("template.muscle_map")))),
        ("skull_folder", Path(resolve_template_path(config.get("template.skull")))),
        *((k, config.get(k)) for k in BUILD_KEYS)), lambda: _build_muscles(fit, cranium, mandible, config))


def _build_muscles(fit, cranium, mandible, config) -> list:
    """:func:`built_muscles` without the cache."""
    from faceforge.anatomy.muscles.build import build_muscles_on
    from faceforge.anatomy.muscles.muscle_map import load_muscle_map
    from faceforge.anatomy.skull import load_skull
    from faceforge.exceptions import StageError, TemplateError
    from faceforge.geometry.mirror import Mirror
    from faceforge.io.templates import resolve_template_path

    specs = load_muscle_map(resolve_template_path(config.get("template.muscle_map")),
                            load_skull(resolve_template_path(config.get("template.skull"))))
    start = fit["muscle_map_start"]
    points = {str(n): fit["muscle_map_points"][start[i]:start[i + 1]]
              for i, n in enumerate(fit["muscle_map_names"])}
    fitted = []
    for spec in specs:
        p = points.get(spec.name)
        if p is None or len(p) != len(spec.points()):
            raise StageError(f"fit.npz has no fitted points for muscle {spec.name!r} of the muscle map; "
                             "rerun `faceforge fit`")
        fitted.append(spec.with_points(p))
    diagonal = float(np.linalg.norm(np.ptp(np.vstack([cranium[0], mandible[0]]), axis=0)))
    stiffness = {"linear": dict(config.get("muscle.linear.stiffness")),
                 "sphincter": dict(config.get("muscle.sphincter.stiffness"))}
    try:
        muscles = build_muscles_on(fitted, cranium, mandible, diagonal, stiffness,
                                   float(config.get("muscle.sphincter.carry_inner")),
                                   float(config.get("muscle.sphincter.protrusion")), mirror=Mirror.from_arrays(fit),
                                   inner_on_bone=bool(config.get("muscle.sphincter.inner_on_bone")),
                                   closure_centre=float(config.get("muscle.sphincter.closure_centre")),
                                   closure_vertical=float(config.get("muscle.sphincter.closure_vertical")),
                                   eversion_up=bool(config.get("muscle.sphincter.eversion_up")),
                                   bulge=float(config.get("muscle.sphincter.bulge")))
    except TemplateError as exc:
        raise StageError(f"fit.npz: {exc.message} (see fit/fit.png; rerun `faceforge fit`, or fit with "
                         "another muscle map)") from None
    return muscles
