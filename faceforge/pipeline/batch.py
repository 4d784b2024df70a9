"""Many heads in one run: plan, run one head, executors, summary (issue 8).

A batch is a list of :class:`HeadJob` (plain, picklable: paths and overrides). Each
head runs its stages (fit, bind, animate) in its own workdir ``<out>/<name>/`` through
the ordinary runner, so the stage cache makes a rerun skip what is done and resume
what was interrupted. :func:`run_head` never raises for a head's own failure: it
returns a :class:`HeadResult` whose ``error`` is the one-line message. Workers share
no in-process state: :func:`run_head` builds its own config and runner from the job.

Executors: in-process (``jobs=1``), local processes (``ProcessPoolExecutor`` with the
spawn context), or a Dask distributed scheduler (``dask[distributed]``, imported on use).

Manifests and head jobs: :mod:`faceforge.pipeline.batch_plan`.


Besides the stages' own files, each head's workdir holds ``batch.log`` (the runner's
lines, appended by every run, tracebacks of unexpected errors) and the remembered inputs
and overrides (``faceforge.yaml``, ``config.yaml``, rewritten by every batch run), so
``faceforge -w <out>/<name> status`` or ``animate`` work on a batch head as on any
workdir. The batch writes ``<out>/batch_report.json`` (:func:`batch_report`).
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

from faceforge.exceptions import ChecksFailed, FaceforgeError, StageError
from faceforge.pipeline.batch_plan import (  # noqa: F401  (the planning API, re-exported)
    DEFAULT_TARGETS, EXPRESSIONS, HeadJob, SharedOptions, check_unique, flatten, import_plugins,
    is_manifest, jobs_from_meshes, load_manifest, make_job, nest, output_path, validate_overrides)

REPORT_NAME = "batch_report.json"
HEAD_LOG = "batch.log"
#: stages whose report.json is summarized in the batch report
METRIC_STAGES = ("fit", "bind", "animate")
#: (stage, dotted key, column title) shown in the terminal table when present
HEADLINE_METRICS = (("fit", "landmarks.max_residual", "fit resid"),
                    ("bind", "regions.face_front.fraction.bound", "bound front"),
                    ("animate", "checks.ok", "checks"))


@dataclass
class HeadResult:
    """Outcome of one head (JSON-ready via :meth:`as_dict`).

    ``stages`` maps a stage name to ``{"state": "ran"|"cached"|"failed"|"not run",
    "seconds": float}`` (seconds of this run; 0 when cached). ``metrics`` holds the
    numeric/boolean/string leaves of the fit, bind and animate ``report.json`` as dotted keys.
    """

    name: str
    workdir: str
    mesh: str = ""
    status: str = "failed"
    error: str | None = None
    stages: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)
    seconds: float = 0.0
    #: failed because a stage's result failed its checks (not an error)
    failed_checks: bool = False

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_dict(self) -> dict:
        return asdict(self)


# --------------------------------------------------------------------------- one head

def _append_log(path: Path, message: str) -> None:
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
    with open(path, "a", encoding="utf-8") as fh:
        for line in str(message).splitlines() or [""]:
            fh.write(f"{stamp} {line}\n")


def head_config(job: HeadJob):
    """The head's validated Config: defaults <- ``config_file`` <- ``overrides``."""
    from faceforge.io.config import build_config, read_config_file, validate_tree

    layers = []
    if job.config_file:
        layers.append(read_config_file(job.config_file))
    if job.overrides:
        layers.append(validate_tree(nest(job.overrides), f"{job.name}: set", {}, Path(job.base)))
    return build_config(layers), layers


def _remember(workspace, layers, params: Mapping) -> None:
    """Write the workdir's remembered inputs and overrides, so single-head commands agree."""
    from faceforge.io.config import merge_trees
    from faceforge.io.stagefiles import save_yaml

    workspace.save_params(params)
    tree: dict = {}
    for layer in layers:
        tree = merge_trees(tree, layer.tree)
    if tree:
        save_yaml(workspace.config_path, tree, header="config overrides of this head (written by faceforge batch)")
    elif workspace.config_path.exists():
        workspace.config_path.unlink()


#: FAP-mapping inputs of the animate/calibrate stages (names as their modules declare them)
_MAPPING_INPUTS = {"fap_mapping", "animate_mapping", "calibration"}


def _head_params(job: HeadJob, config, root: Path, targets: Sequence[str]) -> dict:
    """Stage params of the head: mesh, landmarks, the FAP track and the FAP mapping."""
    from faceforge.io.landmarks import default_landmark_path
    from faceforge.pipeline.stage import stage_order

    landmarks = Path(job.landmarks or default_landmark_path(job.mesh)).absolute()
    # no file next to the mesh: the landmarks stage detects them (an explicit, absent file stays an error)
    params = {"mesh": str(Path(job.mesh).absolute()),
              "landmarks": str(landmarks) if job.landmarks or landmarks.exists() else None}
    needed = {n.rstrip("?") for s in stage_order(targets) for n in s.inputs}
    if "fap" in needed:
        params["fap"] = str(Path(job.fap).absolute()) if job.fap else str(_expression_fap(job, config, root))
    if needed & _MAPPING_INPUTS:   # as `faceforge animate` does: the calibrated mapping if there is one
        from faceforge.pipeline.mapping import calibrated_mapping_path, mapping_template_path

        template, calibrated = str(mapping_template_path(config)), calibrated_mapping_path(root)
        calibrated = str(calibrated) if calibrated.exists() else ""
        # the playback stages play the calibrate stage's mapping (upstream of them): no animate_mapping
        known = {"fap_mapping": template, "calibration": calibrated}
        params.update({k: v for k, v in known.items() if k in needed})
    return params


def _expression_fap(job: HeadJob, config, root: Path) -> Path:
    """Write the job's expression as a FAP file in the workdir (its content keys the cache)."""
    from faceforge.mpeg4 import expression_track, write_fap

    if job.expression is None:
        raise StageError("no FAP track or expression given", job.mesh)
    seconds = job.seconds or float(config.get("animate.expression_seconds"))
    track = expression_track(job.expression, intensity=job.intensity, fps=float(config.get("animate.fps")),
                             seconds=seconds, ramp=float(config.get("animate.expression_ramp")))
    path = root / "inputs" / f"expression_{job.expression}_{job.intensity:g}_{seconds:g}s.fap"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_fap(path, track)
    return path


def report_metrics(report: Mapping) -> dict:
    """Dotted scalar leaves (numbers, booleans, short strings) of a stage's report.json."""
    out = {}
    for key, value in flatten(report).items():
        if isinstance(value, (bool, int, float)) or (isinstance(value, str) and len(value) <= 80):
            out[key] = value
        elif value is None:
            out[key] = None
    return out


def _collect(result: HeadResult, root: Path) -> None:
    """Metrics from the fit/bind reports and the output paths of every complete stage."""
    import json

    for name in METRIC_STAGES:
        path = root / name / "report.json"
        if path.exists():
            try:
                result.metrics[name] = report_metrics(json.loads(path.read_text(encoding="utf-8")))
            except (OSError, ValueError):
                result.metrics[name] = {}
    for name in result.stages:
        folder = root / name
        if (folder / "stage.json").exists():
            result.outputs[name] = sorted(str(p) for p in folder.iterdir() if p.name != "stage.json")


def _export(job: HeadJob, root: Path, log: Callable[[str], None]) -> str:
    """Write the animate stage's frames to ``job.output`` with the user's polygons."""
    from faceforge.io.export import export_for_mesh, up_axis_of
    from faceforge.io.stagefiles import load_npz
    from faceforge.fit.orientation import user_rotation

    animation = root / "animate" / "animation.npz"
    if not animation.exists():
        raise StageError("no animation to export (the animate stage did not run)", root)
    d = load_npz(animation)
    written, notes = export_for_mesh(job.output, d["frames"], job.mesh, float(d["fps"]),
                                     up_axis_of(user_rotation(root / "fit")))
    for note in notes:
        log(f"export: note: {note}")
    return str(written)


def _stage_logger(path: Path, name: str) -> Callable[[str], None]:
    """Runner lines into the head's log, without the repeated "<upstream>: up to date"."""
    def log(message: str) -> None:
        if not (message.endswith(": up to date") and not message.startswith(f"{name}:")):
            _append_log(path, message)
    return log


def run_head(job: HeadJob) -> HeadResult:
    """Bring one head's stages up to date in its workdir; never raises for the head's own errors.

    A :class:`FaceforgeError` becomes ``result.error`` (its one-line message); any
    other exception becomes ``"<Type>: <message>"`` with its traceback in ``batch.log``.
    Runs anywhere: it reads only the job and files.
    """
    from faceforge.pipeline import runner
    from faceforge.pipeline.result_checks import enforce
    from faceforge.pipeline.stage import stage_order

    start = time.perf_counter()
    root = Path(job.workdir)
    root.mkdir(parents=True, exist_ok=True)
    log_path = root / HEAD_LOG
    result = HeadResult(job.name, str(root), job.mesh)
    _append_log(log_path, f"batch: head {job.name} ({job.mesh}) pid {os.getpid()}")
    current = None
    try:
        import_plugins(job.plugins)
        order = [s.name for s in stage_order(job.targets)]
        result.stages = {name: {"state": "not run", "seconds": 0.0} for name in order}
        config, layers = head_config(job)
        workspace = runner.Workspace(root)
        params = {**workspace.load_params(), **_head_params(job, config, root, job.targets)}
        _remember(workspace, layers, params)
        for name in order:
            current, t0 = name, time.perf_counter()
            statuses = runner.run(workspace, config, params, [name], log=_stage_logger(log_path, name))
            status = next(s for s in statuses if s.stage.name == name)
            enforce(workspace.stage_dir(name), name, job.keep_going, lambda m: _append_log(log_path, m))
            result.stages[name] = {"state": "ran" if status.ran else "cached",
                                   "seconds": round(status.seconds if status.ran else 0.0, 3)}
            current = None
        if job.output:
            current = "export"
            result.outputs["export"] = _export(job, root, lambda m: _append_log(log_path, m))
            current = None
        result.status = "ok"
    except FaceforgeError as exc:
        result.error = str(exc)
        result.failed_checks = isinstance(exc, ChecksFailed)
    except Exception as exc:  # a bug must fail this head only, with its traceback kept
        result.error = f"{type(exc).__name__}: {exc}".splitlines()[0]
        _append_log(log_path, traceback.format_exc())
    if current is not None and current in result.stages:
        result.stages[current] = {"state": "failed", "seconds": round(time.perf_counter() - t0, 3)}
    if result.error:
        where = f" in {current}" if current else ""
        _append_log(log_path, f"batch: failed{where}: {result.error}")
    _collect(result, root)
    result.seconds = round(time.perf_counter() - start, 3)
    _append_log(log_path, f"batch: {result.status} in {result.seconds:.1f} s")
    return result


# --------------------------------------------------------------------------- executors

def _limit_threads(threads: int) -> None:
    """Worker initializer: cap BLAS/numba threads, and die with the parent (Linux)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(var, str(threads))
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except OSError:
            pass


def _failed(job: HeadJob, message: str) -> HeadResult:
    return HeadResult(job.name, job.workdir, job.mesh, status="failed", error=message)


def _pool(workers: int):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    threads = max(1, (os.cpu_count() or 1) // workers)
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_limit_threads, initargs=(threads,))


def run_local(jobs: Sequence[HeadJob], n_jobs: int,
              on_result: Callable[[HeadResult], None] = lambda r: None) -> list[HeadResult]:
    """Run the heads in ``n_jobs`` spawned processes (in this process when ``n_jobs == 1``).

    A worker that dies (killed, out of memory, a crash in native code) breaks the pool;
    the heads it left unfinished then run one at a time, each in a fresh process, so
    only the head that kills its process fails ("worker process died").
    """
    if n_jobs <= 1 or len(jobs) <= 1:
        results = []
        for job in jobs:
            results.append(run_head(job))
            on_result(results[-1])
        return results
    import multiprocessing
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

    done: dict[int, HeadResult] = {}
    others = set(multiprocessing.active_children())
    pool = _pool(min(n_jobs, len(jobs)))
    try:
        futures = {pool.submit(run_head, job): i for i, job in enumerate(jobs)}
        for future in as_completed(futures):
            try:
                done[futures[future]] = future.result()
            except BrokenProcessPool:
                continue
            on_result(done[futures[future]])
    except BaseException:   # Ctrl-C: stop now; the killed heads' temp folders go on the next run
        pool.shutdown(wait=False, cancel_futures=True)
        for process in set(multiprocessing.active_children()) - others:
            process.kill()
        raise
    pool.shutdown()
    for i in [i for i in range(len(jobs)) if i not in done]:   # after a worker died: isolate
        with _pool(1) as pool:
            try:
                done[i] = pool.submit(run_head, jobs[i]).result()
            except BrokenProcessPool:
                done[i] = _failed(jobs[i], "worker process died (killed, out of memory or crashed)")
        on_result(done[i])
    return [done[i] for i in range(len(jobs))]


def run_dask(jobs: Sequence[HeadJob], scheduler: str,
             on_result: Callable[[HeadResult], None] = lambda r: None, timeout: str = "15s") -> list[HeadResult]:
    """Run the heads on the Dask distributed scheduler at ``scheduler`` (``tcp://host:port``).

    Workers must be able to import faceforge and read the heads' paths (a shared
    filesystem). Each head is one task: one that raises is not retried; one whose worker
    dies is rescheduled by Dask (``distributed.scheduler.allowed-failures``), then fails alone.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise StageError("--scheduler needs dask.distributed: pip install 'faceforge[dask]'") from None
    try:
        client = Client(scheduler, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        raise StageError(f"cannot reach the Dask scheduler: {exc}".splitlines()[0], scheduler) from None
    done: dict[int, HeadResult] = {}
    futures = []
    try:
        futures = client.map(run_head, list(jobs), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for future in as_completed(futures):
            i = index[future.key]
            try:
                done[i] = future.result()
            except Exception as exc:  # worker lost, unpicklable result: this head fails alone
                done[i] = _failed(jobs[i], f"dask task failed: {type(exc).__name__}: {exc}".splitlines()[0])
            on_result(done[i])
    except BaseException:   # Ctrl-C: cancel what has not finished
        client.cancel(futures, force=True)
        raise
    finally:
        client.close()
    return [done[i] for i in range(len(jobs))]


def run_batch(jobs: Sequence[HeadJob], n_jobs: int | None = None, scheduler: str | None = None,
              on_result: Callable[[HeadResult], None] = lambda r: None) -> list[HeadResult]:
    """Run every head with the chosen executor; results in the order of ``jobs``."""
    if scheduler:
        return run_dask(jobs, scheduler, on_result)
    return run_local(jobs, n_jobs or os.cpu_count() or 1, on_result)


# --------------------------------------------------------------------------- summary

def batch_report(results: Sequence[HeadResult], out_dir: str | Path, seconds: float,
                 executor: str) -> dict:
    """The JSON report: counts, wall time, heads per minute and one entry per head."""
    ok = sum(r.ok for r in results)
    stopped = sum(r.status == "interrupted" for r in results)
    return {"out": str(Path(out_dir).absolute()), "executor": executor, "heads": len(results), "ok": ok,
            "failed": len(results) - ok - stopped, "interrupted": stopped, "seconds": round(seconds, 3),
            "heads_per_minute": round(60.0 * len(results) / seconds, 3) if seconds > 0 else None,
            "results": [r.as_dict() for r in results]}


def _cell(stage: Mapping | None) -> str:
    if not stage:
        return "-"
    state, secs = stage["state"], stage["seconds"]
    return {"ran": f"{secs:.1f}s", "cached": "cached", "failed": f"FAIL {secs:.1f}s"}.get(state, "-")


def format_summary(results: Sequence[HeadResult]) -> str:
    """A plain-text table: head, status, per-stage time (or cached), headline metrics, error."""
    stages: list[str] = []
    for r in results:
        stages += [s for s in r.stages if s not in stages]
    metrics = [(st, key, title) for st, key, title in HEADLINE_METRICS
               if any(key in r.metrics.get(st, {}) for r in results)]
    header = ["head", "status"] + stages + [title for _, _, title in metrics] + ["total"]
    rows = []
    for r in results:
        cells = [r.name, r.status] + [_cell(r.stages.get(s)) for s in stages]
        for st, key, _ in metrics:
            value = r.metrics.get(st, {}).get(key)
            cells.append(f"{value:.3g}" if isinstance(value, float) else ("-" if value is None else str(value)))
        rows.append(cells + [f"{r.seconds:.1f}s"])
    widths = [max(len(str(row[i])) for row in [header] + rows) for i in range(len(header))]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(row, widths)).rstrip() for row in [header] + rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    errors = [f"{r.name}: {r.error}" for r in results if r.status == "failed"]
    counts = {s: sum(r.status == s for r in results) for s in ("ok", "failed", "interrupted")}
    tail = f"{counts['ok']} of {len(results)} heads ok" + "".join(
        f", {counts[s]} {s}" for s in ("failed", "interrupted") if counts[s]) + (":" if errors else "")
    return "\n".join(lines + ["", tail] + [f"  {e}" for e in errors])
