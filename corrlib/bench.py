"""Benchmark runner with the standard protocol (``corr bench``).

Dataset layouts
---------------
* Published-benchmark layout: meshes ``*.off`` in the folder, per-shape
  ground truth ``corres/<name>.vts`` (1-based rows that correspond across
  shapes), optional mirrored ``corres/<name>.sym.vts`` (or next to the
  meshes), and a pairs file (``pairs.txt`` or ``--pairs``) of tab- or
  space-separated shape names.
* A folder of meshes with the same connectivity (no ``corres/``): the
  ground truth is the identity.
Without a pairs file every ordered pair of distinct shapes is run.

Every (method, pair) is a job: it loads both meshes, runs the method from
the registry, and returns the map and the per-point geodesic errors
(Princeton protocol, :func:`corrlib.evaluation.geodesic_errors`). Jobs run
in a local process pool or, with a scheduler address, on a Dask cluster
(through Dask's ``concurrent.futures`` executor: one code path). The
client writes every result atomically as soon as it arrives
(``maps/<method>/<source>__<target>.txt``, ``records/...json``), so an
interrupted run continues where it stopped; a failing pair is recorded with
its error and does not stop the run.

Outputs: ``errors.csv`` (one row per method and pair), ``summary.md`` and
``summary.json`` (per method: mean error, fractions within 0.025 / 0.05 /
0.1, the same with the mirrored ground truth accepted, median and total
runtime, peak memory), ``curves.png`` (cumulative error curves of all
methods) and ``environment.json`` (versions, methods with parameters,
machine).

External maps (``--maps NAME=FOLDER``): map files produced elsewhere
(``<source>__<target>.txt`` or ``<source>_<target>.map``, 0-based target
index per source vertex) are evaluated with the same protocol.
"""

from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from corrlib.errors import CorrError, FileFormatError, InputError, ParameterError
from corrlib.io import lost_working_folder, read_text, suffixes
from corrlib.parallel import job_executor
from corrlib.progress import peak_rss_mb

#: dataset meshes: the formats of :data:`corrlib.io.FORMATS` with a vertex order (ground truth indexes it)
MESH_SUFFIXES = suffixes("mesh", readable=True, vertex_order=True)


@dataclass
class Dataset:
    """Shapes, ground truth and pairs of a benchmark folder."""

    folder: Path
    shapes: dict[str, Path]
    pairs: list[tuple[str, str]]
    gt: dict[str, Path] = field(default_factory=dict)
    gt_sym: dict[str, Path] = field(default_factory=dict)

    @property
    def identity(self) -> bool:
        return not self.gt


def load_dataset(folder, pairs_file=None, *, require_pairs: bool = True) -> Dataset:
    """Discover a dataset (see the module docstring for the layouts).

    ``require_pairs=False`` accepts a single shape (benchmarks that match a shape with itself).
    """
    root = Path(folder)
    if not root.is_dir():
        raise FileFormatError(f"{root}: not a folder{lost_working_folder(root)}")
    shapes = {p.stem: p for p in sorted(root.iterdir()) if p.suffix.lower() in MESH_SUFFIXES}
    if not shapes:
        raise FileFormatError(f"{root}: no meshes ({', '.join(MESH_SUFFIXES)})")
    gt, gt_sym = {}, {}
    for base in (root / "corres", root):
        if base.is_dir():
            for p in base.glob("*.vts"):
                name = p.name[:-len(".sym.vts")] if p.name.endswith(".sym.vts") else p.stem
                (gt_sym if p.name.endswith(".sym.vts") else gt).setdefault(name, p)
    if gt:
        missing = sorted(set(shapes) - set(gt))
        if missing:
            raise FileFormatError(f"{root}: no ground truth (.vts) for {', '.join(missing[:5])}")
    pairs_path = Path(pairs_file) if pairs_file else root / "pairs.txt"
    if pairs_path.exists():
        pairs, first_line = [], {}
        for number, line in enumerate(read_text(pairs_path, "pairs").splitlines(), 1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            names = line.split()
            if len(names) != 2:
                raise FileFormatError(f"{pairs_path}:{number}: expected two shape names, got {line!r}")
            names = [Path(n).stem for n in names]
            for n in names:
                if n not in shapes:
                    raise FileFormatError(f"{pairs_path}:{number}: unknown shape {n!r}")
            pair = (names[0], names[1])
            if pair in first_line:  # it would be run, and counted, twice
                raise FileFormatError(f"{pairs_path}:{number}: the pair {pair[0]} {pair[1]} again (first on line "
                                      f"{first_line[pair]})")
            first_line[pair] = number
            pairs.append(pair)
    elif pairs_file:
        raise FileFormatError(f"{pairs_path}: pairs file not found")
    else:
        names = list(shapes)
        pairs = [(a, b) for a in names for b in names if a != b]
    if not pairs and require_pairs:
        raise FileFormatError(f"{root}: no pairs to run")
    return Dataset(root, shapes, pairs, gt, gt_sym)


def checked_ground_truth(data: Dataset, pairs) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The dataset's ground truth, checked before any method runs: ``({name: .vts rows},
    {name: .sym.vts rows})`` (0-based), both empty for meshes of one connectivity (the identity is their ground
    truth).

    Row r of the two ``.vts`` files of a pair is the same surface point, so a pair's files (and a target's
    ``.sym.vts`` against its ``.vts``) must have as many rows, each index within its mesh; without ``.vts``
    files the two meshes of a pair must share their faces. Every violation is a
    :class:`~corrlib.errors.FileFormatError` naming the file (or the two meshes). A mesh that cannot be read is
    left out here: its pairs fail in their jobs, with the reason, and the run goes on.

    Parameters
    ----------
    data : Dataset
    pairs : iterable of (str, str)
        The shape names whose rows are compared.
    """
    from corrlib.io import load_mesh, load_vts

    if data.gt_sym and not data.gt:
        first = next(iter(data.gt_sym.values()))
        raise FileFormatError(f"{first}: mirrored ground truth (.sym.vts) without the ground truth itself; give "
                              f"corres/<name>.vts for every mesh")
    meshes = {}
    for name, path in data.shapes.items():
        try:
            meshes[name] = load_mesh(path)
        except CorrError:
            continue
    rows = {name: load_vts(path, meshes[name].n_vertices if name in meshes else None)
            for name, path in data.gt.items()}
    mirror = {name: load_vts(path, meshes[name].n_vertices if name in meshes else None)
              for name, path in data.gt_sym.items() if name in data.shapes}
    for name, sym in mirror.items():
        if sym.size != rows[name].size:
            raise FileFormatError(f"{data.gt_sym[name]}: {sym.size} rows against {rows[name].size} in "
                                  f"{data.gt[name].name}; a mirrored ground truth has a row for every row")
    for a, b in pairs:
        if a not in meshes or b not in meshes:
            continue
        if rows and rows[a].size != rows[b].size:
            raise FileFormatError(f"{data.gt[a]} has {rows[a].size} rows and {data.gt[b]} {rows[b].size}: the rows "
                                  f"of a pair's .vts files are corresponding points, so their counts must be equal")
        n_a, n_b = meshes[a].n_vertices, meshes[b].n_vertices
        if not rows and (n_a != n_b or not np.array_equal(meshes[a].faces, meshes[b].faces)):
            found = f"{n_a} and {n_b} vertices" if n_a != n_b else f"both {n_a} vertices, other faces"
            raise FileFormatError(f"{data.shapes[a]} and {data.shapes[b]}: without .vts files the ground truth is "
                                  f"the identity, which needs one connectivity ({found}); give corres/<name>.vts "
                                  f"files")
    return rows, mirror


@dataclass(frozen=True)
class MethodRun:
    """A method of the registry with parameters, under a label (one column of the results)."""

    label: str
    name: str
    params: dict = field(default_factory=dict)


def parse_method(text: str) -> MethodRun:
    """``NAME[:key=value,key=value][@LABEL]`` (values as on the command line)."""
    from corrlib.methods import get_method, make_params

    label = None
    if "@" in text:
        text, label = text.rsplit("@", 1)
    name, _, rest = text.partition(":")
    params = {}
    for item in filter(None, rest.split(",")):
        if "=" not in item:
            raise ParameterError(f"method parameter {item!r} must be key=value")
        key, value = item.split("=", 1)
        params[key.strip()] = value.strip()
    spec = get_method(name.strip())
    make_params(spec.params, **params)  # validate now, not in a worker
    return MethodRun(label or (name.strip() if not params else f"{name.strip()}({rest})"), spec.name, params)


def methods_from_toml(path) -> list[MethodRun]:
    """``[[method]]`` tables with ``name``, optional ``label`` and a ``params`` table."""
    import tomllib

    from corrlib.methods import get_method, make_params

    try:
        doc = tomllib.loads(read_text(path, "methods"))
    except (FileFormatError, tomllib.TOMLDecodeError) as exc:
        raise FileFormatError(f"{path}: cannot read the methods file: {exc}") from None
    tables = doc.get("method", [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise FileFormatError(f"{path}: 'method' must be an array of tables ([[method]] sections), got "
                              f"{type(tables).__name__}")
    out = []
    for i, table in enumerate(tables, 1):
        unknown = sorted(set(table) - {"name", "label", "params"})
        if unknown:
            raise FileFormatError(f"{path}: method {i} has unknown keys {', '.join(unknown)} (use name, label, "
                                  f"params)")
        for key, kind in (("name", str), ("label", str), ("params", dict)):
            if key in table and not isinstance(table[key], kind):
                raise FileFormatError(f"{path}: method {i}: {key} must be a {'table' if kind is dict else 'string'}, "
                                      f"got {table[key]!r}")
        if "name" not in table:
            raise FileFormatError(f"{path}: method {i} has no name")
        spec = get_method(table["name"])
        params = dict(table.get("params", {}))
        make_params(spec.params, **params)
        out.append(MethodRun(table.get("label", spec.name), spec.name, params))
    if not out:
        raise FileFormatError(f"{path}: no [[method]] tables")
    return out


# ----------------------------------------------------------------------------- jobs


@dataclass(frozen=True)
class Job:
    """One (method, pair) to run in a worker; everything a worker needs, picklable."""

    method: MethodRun | None
    source: str
    target: str
    source_path: str
    target_path: str
    gt: tuple[str | None, str | None, str | None]  # source .vts, target .vts, target .sym.vts
    geodesics: str = "exact"
    external_map: str | None = None

    @property
    def key(self) -> str:
        return f"{self.source}__{self.target}"


def run_job(job: Job) -> dict:
    """Run one job (in a worker): the record, the map and the per-point errors. Never raises."""
    from corrlib.evaluation import matched_errors
    from corrlib.io import load_map, load_mesh, load_vts

    record = {"source": job.source, "target": job.target, "status": "ok", "error": ""}
    map_xy = errors = errors_sym = None
    try:
        start = time.perf_counter()
        source, target = load_mesh(job.source_path), load_mesh(job.target_path)
        load_time = time.perf_counter() - start
        if job.external_map is not None:
            map_xy = load_map(job.external_map, n_target=target.n_vertices, n_source=source.n_vertices,
                              allow_unmatched=True)
            runtime = 0.0
        else:
            from corrlib.methods import solve

            start = time.perf_counter()
            result = solve(job.method.name, source, target, **job.method.params)
            runtime = time.perf_counter() - start
            map_xy = result.map_xy
        start = time.perf_counter()
        if job.gt[0] is None:
            if source.n_vertices != target.n_vertices:
                raise InputError(f"identity ground truth needs equal vertex counts, got {source.n_vertices} and "
                                 f"{target.n_vertices}")
            gx = gy = np.arange(source.n_vertices)
            sym = None
        else:
            gx = load_vts(job.gt[0], source.n_vertices)
            gy = load_vts(job.gt[1], target.n_vertices)
            sym = load_vts(job.gt[2], target.n_vertices) if job.gt[2] else None
        report, matched = matched_errors(map_xy, target, gx, gy, gt_target_sym=sym, method=job.geodesics)
        if report is None:
            raise InputError(f"the map leaves all {matched.size} ground-truth rows unmatched")
        errors, errors_sym = report.errors, report.errors_sym
        record.update(report.summary(), unmatched=float(np.mean(~matched)))
        evaluation = time.perf_counter() - start
        record.update(runtime=runtime, load_time=load_time, evaluation_time=evaluation,
                      overhead=load_time + evaluation,
                      peak_memory_mb=peak_rss_mb(), n_source=source.n_vertices, n_target=target.n_vertices)
    except Exception as exc:  # a failing pair is recorded, the run goes on
        record.update(status="failed", error=f"{type(exc).__name__}: {exc}")
    return {"record": record, "map_xy": map_xy, "errors": errors, "errors_sym": errors_sym}


# ----------------------------------------------------------------------------- runner


def _read_record(path: Path) -> dict | None:
    """A pair's record (JSON object), or None where the file is not one (cut short or edited by hand)."""
    try:
        record = json.loads(read_text(path, "record"))
    except (FileFormatError, json.JSONDecodeError):
        return None
    return record if isinstance(record, dict) else None


def _label_dir(label: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.()=," else "_" for c in label)


class Runner:
    """Runs the jobs of a benchmark into an output folder (resumable).

    Parameters
    ----------
    dataset : Dataset
    methods : list of MethodRun
    out : path
    external : dict of label -> folder, optional
        Map files made elsewhere, evaluated with the same protocol.
    geodesics : {"exact", "heat", "graph"}
    """

    def __init__(self, dataset: Dataset, methods: list[MethodRun], out, *, external=None,
                 geodesics: str = "exact"):
        self.dataset = dataset
        self.methods = list(methods)
        self.external = dict(external or {})
        if not self.methods and not self.external:
            raise ParameterError("give at least one method or a folder of external maps")
        labels = [m.label for m in self.methods] + list(self.external)
        if len(set(labels)) != len(labels):
            raise ParameterError(f"method labels must be unique, got {labels}")
        folders = [_label_dir(label) for label in labels]
        for label, folder in zip(labels, folders):
            if folder.strip(".") == "":
                raise ParameterError(f"method label {label!r} names no folder; use letters or digits")
            if folders.count(folder) > 1:
                raise ParameterError(f"method labels {[l for l, f in zip(labels, folders) if f == folder]} share "
                                     f"the results folder {folder!r}; choose labels that differ in letters or "
                                     f"digits")
        self.out = Path(out)
        self.geodesics = geodesics
        self._settings = {}

    def jobs(self) -> list[tuple[str, Job]]:
        ds = self.dataset
        out = []
        for a, b in ds.pairs:
            gt = (None, None, None) if ds.identity else (str(ds.gt[a]), str(ds.gt[b]),
                                                          str(ds.gt_sym[b]) if b in ds.gt_sym else None)
            base = dict(source=a, target=b, source_path=str(ds.shapes[a]), target_path=str(ds.shapes[b]), gt=gt,
                        geodesics=self.geodesics)
            for m in self.methods:
                out.append((m.label, Job(method=m, **base)))
            for label, folder in self.external.items():
                candidates = [Path(folder) / f"{a}__{b}.txt", Path(folder) / f"{a}_{b}.map",
                              Path(folder) / f"{a}__{b}.map"]
                found = next((str(p) for p in candidates if p.exists()), str(candidates[0]))
                out.append((label, Job(method=None, external_map=found, **base)))
        return out

    def _record_path(self, label: str, job: Job) -> Path:
        return self.out / "records" / _label_dir(label) / f"{job.key}.json"

    def settings(self, label: str) -> dict:
        """What produced a label's results (stored with each record): the method with every parameter, or the
        folder of external maps, and the geodesics of the evaluation (JSON values; formed once per label)."""
        if label not in self._settings:
            method = next((m for m in self.methods if m.label == label), None)
            what = {"maps": str(self.external[label])} if method is None else {"method": method.name,
                                                                                "params": _all_params(method)}
            self._settings[label] = json.loads(json.dumps({**what, "geodesics": self.geodesics}, default=str))
        return self._settings[label]

    def pending(self) -> list[tuple[str, Job]]:
        """Jobs without a record yet, or whose record is a failure (what a resumed run still has to do; a
        failure is retried, its input may have been fixed). A record made with other settings under the same
        label (:meth:`settings`) is refused by name: its numbers would be reported as this run's."""
        todo, clashes = [], []
        for label, job in self.jobs():
            path = self._record_path(label, job)
            if not path.exists():
                todo.append((label, job))
                continue
            record = _read_record(path)
            if record is None:  # damaged (cut short, edited): run again, its new record replaces it
                todo.append((label, job))
                continue
            stored = record.get("settings", self.settings(label))  # records of older versions carry none
            if stored != self.settings(label):
                clashes.append((label, stored))
            elif record.get("status") == "failed":
                todo.append((label, job))
        if clashes:
            label, stored = clashes[0]
            now = self.settings(label)
            changed = sorted(k for k in set(stored) | set(now) if stored.get(k) != now.get(k))
            if "params" in changed:
                changed.remove("params")
                changed += sorted(f"{k}={stored['params'].get(k)!r} → {now['params'].get(k)!r}"
                                  for k in set(stored["params"]) | set(now["params"])
                                  if stored["params"].get(k) != now["params"].get(k))
            raise ParameterError(f"{self.out} holds {len(clashes)} result(s) of {label!r} made with other settings "
                                 f"({', '.join(changed)}); choose a new output folder (-o) or another label")
        return todo

    def _store(self, label: str, job: Job, outcome: dict) -> None:
        from corrlib.io import atomic_write, save_map

        rec = dict(outcome["record"], method=label, settings=self.settings(label))
        folder = self.out / "maps" / _label_dir(label)
        if outcome["map_xy"] is not None and job.external_map is None:
            folder.mkdir(parents=True, exist_ok=True)
            save_map(folder / f"{job.key}.txt", outcome["map_xy"])
        if outcome["errors"] is not None:
            err_dir = self.out / "errors" / _label_dir(label)
            err_dir.mkdir(parents=True, exist_ok=True)
            arrays = {"errors": outcome["errors"]}
            if outcome["errors_sym"] is not None:
                arrays["errors_sym"] = outcome["errors_sym"]
            with atomic_write(err_dir / f"{job.key}.npz", "wb") as fh:
                np.savez(fh, **arrays)
        path = self._record_path(label, job)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path) as fh:
            json.dump(rec, fh, indent=1)

    def run(self, *, jobs: int | None = None, scheduler: str | None = None, callback=None,
            limit: int | None = None) -> dict:
        """Run every pending job, then write the summary. ``limit`` stops after that many jobs (tests). The
        dataset's ground truth is checked first (:func:`checked_ground_truth`)."""
        checked_ground_truth(self.dataset, self.dataset.pairs)
        todo = self.pending()
        if limit is not None:
            todo = todo[:limit]
        if not todo:
            self._write_environment(jobs, scheduler)
        else:  # the workers (the number asked for, the scheduler reached) before anything is written
            with job_executor(jobs, scheduler) as pool:
                from concurrent.futures import as_completed

                self._write_environment(jobs, scheduler)
                futures = {pool.submit(run_job, job): (label, job) for label, job in todo}
                for done, future in enumerate(as_completed(futures), 1):
                    label, job = futures[future]
                    outcome = future.result()
                    self._store(label, job, outcome)
                    if callback is not None:
                        callback(done, len(todo), label, outcome["record"])
        return self.summarize()

    def _write_environment(self, jobs, scheduler) -> None:
        """The output folder (created) and its ``environment.json``."""
        from corrlib.io import atomic_write, environment

        env = environment()
        env.update(machine=platform.machine(), processor=platform.processor(), cores=os.cpu_count(),
                   jobs=jobs, scheduler=scheduler, geodesics=self.geodesics,
                   dataset=str(self.dataset.folder), pairs=len(self.dataset.pairs),
                   methods=[{"label": m.label, "name": m.name, "params": m.params,
                             "all_params": _all_params(m)} for m in self.methods],
                   external=self.external)
        self.out.mkdir(parents=True, exist_ok=True)
        with atomic_write(self.out / "environment.json") as fh:
            json.dump(env, fh, indent=1, default=str)

    def records(self) -> list[dict]:
        out = []
        for label, job in self.jobs():
            path = self._record_path(label, job)
            record = _read_record(path) if path.exists() else None
            if record is not None:
                out.append(record)
        return out

    def summarize(self) -> dict:
        """Write errors.csv, summary.md/.json and curves.png from the stored records; return the summary."""
        from corrlib.evaluation import DEFAULT_THRESHOLDS, cumulative_curve
        from corrlib.io import atomic_write

        records = self.records()
        columns = ["method", "source", "target", "status", "mean", "median", "within_0.025", "within_0.05",
                   "within_0.1", "mean_sym", "within_0.05_sym", "unmatched", "runtime", "overhead", "peak_memory_mb",
                   "error"]
        with atomic_write(self.out / "errors.csv") as fh:
            fh.write(",".join(columns) + "\n")
            for rec in records:
                fh.write(",".join(csv_cell(rec.get(c, "")) for c in columns) + "\n")
        summary = {}
        curves = {}
        for label in [m.label for m in self.methods] + list(self.external):
            recs = [r for r in records if r["method"] == label]
            ok = [r for r in recs if r["status"] == "ok"]
            errs, errs_sym = [], []
            for r in ok:
                data = np.load(self.out / "errors" / _label_dir(label) / f"{r['source']}__{r['target']}.npz")
                errs.append(data["errors"])
                if "errors_sym" in data:
                    errs_sym.append(data["errors_sym"])
            entry = {"pairs": len(recs), "failed": len(recs) - len(ok)}
            if errs:
                e = np.concatenate(errs)
                entry.update(mean=float(e.mean()), **{f"within_{t}": float(np.mean(e <= float(t)))
                                                      for t in ("0.025", "0.05", "0.1")})
                if errs_sym:
                    s = np.concatenate(errs_sym)
                    entry.update(mean_sym=float(s.mean()), **{f"within_{t}_sym": float(np.mean(s <= float(t)))
                                                              for t in ("0.025", "0.05", "0.1")})
                runtimes = [r["runtime"] for r in ok]
                entry.update(median_runtime=float(np.median(runtimes)), total_runtime=float(np.sum(runtimes)),
                             median_overhead=float(np.median([r["overhead"] for r in ok])),
                             peak_memory_mb=float(max(r["peak_memory_mb"] for r in ok)))
                curves[label] = cumulative_curve(e, DEFAULT_THRESHOLDS)
            summary[label] = entry
        with atomic_write(self.out / "summary.json") as fh:
            json.dump(summary, fh, indent=1)
        with atomic_write(self.out / "summary.md") as fh:
            fh.write(_markdown(summary))
        if curves:
            from corrlib.plotting import save_error_curves

            save_error_curves(self.out / "curves.png", curves, DEFAULT_THRESHOLDS,
                              title=f"{self.dataset.folder.name}: cumulative geodesic error")
        return summary


def _all_params(method: MethodRun) -> dict:
    """Every parameter of a method run, defaults included (seeds too): what reproduces it."""
    from dataclasses import asdict

    from corrlib.methods import get_method, make_params

    return asdict(make_params(get_method(method.name).params, **method.params))


def failure_fields(exc: Exception) -> dict:
    """The row fields of a benchmark match that failed: a named error's message as it is, any other exception
    with its type (a failing match is recorded and the others go on)."""
    return {"status": "failed", "error": str(exc) if isinstance(exc, CorrError) else f"{type(exc).__name__}: {exc}"}


def path_search_fields(result, seconds: float) -> dict:
    """The row fields of a 2D-to-3D match's closed path and its search: contour points, distinct vertices of
    the path, energy, optimality gap, whether it is proven optimal, branch-and-bound iterations, and the
    match's time."""
    search = result.search
    return {"n_points": int(len(result.map_xy)), "distinct_vertices": int(len(np.unique(result.path.vertices))),
            "energy": float(result.energy), "gap": float(search.upper_bound - search.lower_bound),
            "optimal": search.optimal, "iterations": search.iterations, "seconds": seconds}


def csv_cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    text = str(value)
    return '"' + text.replace('"', "'") + '"' if ("," in text or '"' in text) else text


def _markdown(summary: dict) -> str:
    head = ("| method | pairs | failed | mean | ≤0.025 | ≤0.05 | ≤0.1 | mean (sym) | ≤0.05 (sym) | median s | "
            "total s | peak MB |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    rows = []
    for label, e in summary.items():
        def f(key, fmt="{:.3f}"):
            return fmt.format(e[key]) if key in e else "–"
        rows.append(f"| {label} | {e['pairs']} | {e['failed']} | {f('mean')} | {f('within_0.025')} | "
                    f"{f('within_0.05')} | {f('within_0.1')} | {f('mean_sym')} | {f('within_0.05_sym')} | "
                    f"{f('median_runtime', '{:.2f}')} | {f('total_runtime', '{:.1f}')} | "
                    f"{f('peak_memory_mb', '{:.0f}')} |")
    return head + "\n".join(rows) + "\n"


# ----------------------------------------------------------------------------- retrieval benchmark

#: retrieval queries: every contour format of :data:`corrlib.io.FORMATS`
CONTOUR_SUFFIXES = suffixes("contour", readable=True)


def _checked_retrieval_run(queries, out, jobs: int | None, scheduler: str | None) -> Path:
    """Before any query of :func:`retrieval_benchmark` (each would fail alike): the workers' count or address,
    and the output folder, made and writable and not among the queries, which the next run would read."""
    from corrlib.outputs import check_outside, ensure_output_folder
    from corrlib.parallel import check_jobs, check_scheduler_address

    check_jobs(jobs)
    if scheduler is not None:
        check_scheduler_address(scheduler)
    check_outside(out, queries, "output", "queries")
    return ensure_output_folder(out)


def retrieval_benchmark(queries, collection, out, *, params=None, jobs: int | None = None,
                        scheduler: str | None = None, callback=None, ranking: str = "fused",
                        own_meshes=None) -> dict:
    """Rank a collection against every query; average precision per query and class, and their mean.

    Parameters
    ----------
    queries : path
        Folder of silhouette images or contour files, with its subfolders; the
        class of a query is the subfolder it is in (``queries/horse/3.png``) or,
        directly in the folder, its file name without a trailing number
        (``horse-3.png`` -> ``horse``; :func:`~corrlib.retrieval.class_of`).
    collection : path
        Folder of meshes, with its subfolders, classes named the same way
        (``horse/0.off`` or ``horse0.off``).
    out : path
        Writes ``retrieval.csv`` (query, class, AP, rank of the first relevant
        mesh, class margin (:func:`~corrlib.retrieval.class_margin`), top hits, the Princeton Shape Benchmark's
        measures (:func:`~corrlib.retrieval.ranking_measures`), the AP with the query's own mesh left out),
        ``retrieval_pr.csv`` and ``retrieval_pr.png`` (the mean interpolated precision at 11 recall levels,
        :func:`~corrlib.retrieval.interpolated_precision`), ``retrieval_ranking.csv`` (every query's whole
        ranking: rank, mesh, its class, ranking score, matching energy, view dissimilarity, seconds, why a mesh
        failed),
        ``retrieval_summary.json`` and ``retrieval_summary.md``.
    params : Contour3DParams, optional
    jobs, scheduler
        Local processes or a Dask scheduler (see :func:`corrlib.parallel.job_executor`).
    ranking : {"fused", "energy"}
        :func:`~corrlib.retrieval.retrieve`'s ranking.
    own_meshes : path, optional
        The mesh each listed query was made from (:func:`~corrlib.retrieval.read_own_meshes`, read and checked
        before any query): each listed query is also scored with that mesh left out of its ranking
        (:func:`~corrlib.retrieval.ap_without`), and the summary gives the MAP of those and, apart, of the
        queries not listed (:func:`own_mesh_summary`).

    Returns
    -------
    dict
        ``{"map": float, "map_interval": [low, high]`` (95 % bootstrap interval over the queries,
        :func:`~corrlib.retrieval.map_interval`), ``"median_margin": float, "right_class_first": int,
        "per_class": {class: mean AP}, "queries": int, "failed": int, "own_meshes": dict or None,
        "nn", "first_tier", "second_tier", "e_measure", "dcg": their means, "precision_at_recall": (11,), ...}``.
    """
    from corrlib.io import atomic_write, load_contour
    from corrlib.progress import run
    from corrlib.retrieval import (RANKING_MEASURES, ap_without, average_precision, class_margin, class_of,
                                   collection_name, files_under, interpolated_precision, map_interval, mesh_files,
                                   ranking_measures, read_own_meshes, retrieve)

    query_paths = files_under(queries, CONTOUR_SUFFIXES, "query silhouettes or contour files")
    meshes = mesh_files(collection)
    own = {} if own_meshes is None else read_own_meshes(own_meshes, [collection_name(q, queries) for q in query_paths],
                                                         [collection_name(m, collection) for m in meshes])
    out = _checked_retrieval_run(queries, out, jobs, scheduler)
    rows, ranked, failed_meshes = [], [], set()
    for number, q in enumerate(query_paths, 1):
        name = collection_name(q, queries)
        row = {"query": name, "class": class_of(q, queries), "ap": float("nan"), "first_relevant": "",
               "margin": float("nan"), "top": "", **dict.fromkeys(RANKING_MEASURES, float("nan")),
               "ap_own_left_out": float("nan"), "error": ""}
        try:
            hits = run(retrieve(load_contour(q), meshes, params, jobs=jobs, scheduler=scheduler, root=collection,
                                ranking=ranking))
            ranked += [{"query": name, "rank": rank, "mesh": h.name, "class": h.label, "score": h.score,
                        "energy": h.energy, "view_distance": h.view_distance, "seconds": h.seconds, "error": h.error,
                        "curve_length_ratio": h.curve_length_ratio}
                       for rank, h in enumerate(hits, 1)]
            labels = [h.label for h in hits]
            broken = [h for h in hits if h.error]
            if len(broken) == len(hits):
                raise InputError(f"no mesh of the collection could be matched (first: {broken[0].name}: "
                                 f"{broken[0].error})")
            failed_meshes.update(h.name for h in broken)
            if row["class"] not in labels:  # no relevant mesh: the AP is undefined, not 0
                raise InputError(f"no mesh of class {row['class']!r} in the collection")
            row["ap"] = average_precision(labels, row["class"])
            row["first_relevant"] = labels.index(row["class"]) + 1
            row["margin"] = class_margin(labels, [h.score for h in hits], row["class"])
            row["top"] = " ".join(h.name for h in hits[:5])
            row.update(ranking_measures(labels, row["class"]), precision=interpolated_precision(labels, row["class"]))
            if name in own:
                row["ap_own_left_out"] = ap_without([h.name for h in hits], labels, own[name], row["class"])
        except Exception as exc:  # a failing query is recorded, the others go on
            row["error"] = f"{type(exc).__name__}: {exc}"
        rows.append(row)
        if callback is not None:
            callback(number, len(query_paths), row)
    ok = [r for r in rows if not r["error"]]
    precision = np.mean([r["precision"] for r in ok], axis=0) if ok else None
    write_retrieval_tables(out, rows, ranked, precision,
                           f"{Path(queries).name} against {Path(collection).name}, {ranking} ranking")
    per_class = {}
    for r in ok:
        per_class.setdefault(r["class"], []).append(r["ap"])
    margins = [r["margin"] for r in ok if np.isfinite(r["margin"])]
    summary = {"map": float(np.mean([r["ap"] for r in ok])) if ok else None,
               "map_interval": list(map_interval([r["ap"] for r in ok])) if ok else None,
               "median_margin": float(np.median(margins)) if margins else None,
               "right_class_first": sum(m > 0 for m in margins),
               "per_class": {c: float(np.mean(v)) for c, v in sorted(per_class.items())},
               "queries": len(rows), "failed": len(rows) - len(ok), "collection": len(meshes),
               "failed_meshes": sorted(failed_meshes), "own_meshes": own_mesh_summary(ok, own) if own else None,
               **{m: float(np.mean([r[m] for r in ok])) if ok else None for m in RANKING_MEASURES},
               "precision_at_recall": None if precision is None else [float(p) for p in precision]}
    with atomic_write(out / "retrieval_summary.json") as fh:
        json.dump(summary, fh, indent=1)
    with atomic_write(out / "retrieval_summary.md") as fh:
        fh.write(retrieval_summary_text(summary, len(ok), len(margins), ranking))
    return summary


def write_retrieval_tables(out: Path, rows: list[dict], ranked: list[dict], precision, title: str) -> None:
    """:func:`retrieval_benchmark`'s tables: ``retrieval.csv`` (a row per query), ``retrieval_ranking.csv`` (a row
    per query and mesh) and, where a query was answered, the mean interpolated precision at the 11 recall
    levels as ``retrieval_pr.csv`` and ``retrieval_pr.png`` (``precision``: (11,) float or None)."""
    from corrlib.io import atomic_write
    from corrlib.retrieval import RANKING_MEASURES, RECALL_LEVELS

    tables = (("retrieval.csv", ("query", "class", "ap", "first_relevant", "margin", "top", *RANKING_MEASURES,
                                 "ap_own_left_out", "error"), rows),
              ("retrieval_ranking.csv", ("query", "rank", "mesh", "class", "score", "energy", "view_distance",
                                         "seconds", "error", "curve_length_ratio"), ranked))
    for name, columns, table in tables:
        with atomic_write(out / name) as fh:
            fh.write(",".join(columns) + "\n")
            fh.writelines(",".join(csv_cell(r[c]) for c in columns) + "\n" for r in table)
    if precision is None:
        return
    with atomic_write(out / "retrieval_pr.csv") as fh:
        fh.write("recall,precision\n")
        fh.writelines(f"{r:.1f},{p:.6g}\n" for r, p in zip(RECALL_LEVELS, precision))
    from corrlib.plotting import save_precision_recall

    save_precision_recall(out / "retrieval_pr.png", RECALL_LEVELS, precision,
                          title=f"{title}: interpolated precision-recall")


def own_mesh_summary(rows: list[dict], own: dict[str, str]) -> dict:
    """:func:`retrieval_benchmark`'s figures for a list of own meshes, from its answered query ``rows``: the MAP
    of the listed queries with their own mesh left out (``map_left_out`` over ``left_out`` queries; listed
    queries whose class has no other mesh are named in ``no_other_member``) and the MAP of the queries not
    listed (``map_not_listed`` over ``not_listed``); a MAP over no query is None."""
    listed = [r for r in rows if r["query"] in own]
    scored = [r["ap_own_left_out"] for r in listed if np.isfinite(r["ap_own_left_out"])]
    others = [r["ap"] for r in rows if r["query"] not in own]
    return {"map_left_out": float(np.mean(scored)) if scored else None, "left_out": len(scored),
            "no_other_member": [r["query"] for r in listed if not np.isfinite(r["ap_own_left_out"])],
            "map_not_listed": float(np.mean(others)) if others else None, "not_listed": len(others)}


def retrieval_summary_text(summary: dict, answered: int, with_margin: int, ranking: str) -> str:
    """``retrieval_summary.md``: the MAP, its interval, the class margins, the own-mesh figures, the failed
    meshes and the AP per class, from :func:`retrieval_benchmark`'s summary (``answered`` queries, of which
    ``with_margin`` have a class margin)."""
    lines = [(f"mean average precision: {summary['map']:.3f} over {answered} queries" if answered else
              "mean average precision: none (no query was ranked)")
             + f" ({summary['failed']} failed), {summary['collection']} meshes"]
    if answered:
        low, high = summary["map_interval"]
        lines.append(f"95 % bootstrap interval over the queries: {low:.3f}–{high:.3f} (how much the MAP depends on "
                     f"which queries the set holds)")
        lines.append(f"nearest neighbour {summary['nn']:.3f}, first tier {summary['first_tier']:.3f}, second tier "
                     f"{summary['second_tier']:.3f}, E-measure {summary['e_measure']:.3f}, DCG {summary['dcg']:.3f} "
                     f"(the Princeton Shape Benchmark's measures, as the SHREC sketch tracks report them)")
    if summary["median_margin"] is not None:
        lines.append(f"class margin (best other class's {'energy' if ranking == 'energy' else 'score'} against the "
                     f"query class's, relative; retrieval.csv per query): median {summary['median_margin']:+.3f}, "
                     f"the query's class first on {summary['right_class_first']} of {with_margin} queries")
    own = summary["own_meshes"]
    if own is not None:
        def mean(value):
            return "none" if value is None else f"{value:.3f}"
        without = (f"; {len(own['no_other_member'])} have no other mesh of their class: "
                   f"{', '.join(own['no_other_member'])}" if own["no_other_member"] else "")
        lines.append(f"with each listed query's own mesh left out of its ranking: MAP {mean(own['map_left_out'])} "
                     f"over {own['left_out']} queries{without}; the queries not listed: MAP "
                     f"{mean(own['map_not_listed'])} over {own['not_listed']}")
    if summary["failed_meshes"]:
        lines.append(f"meshes that could not be matched (ranked last; see retrieval_ranking.csv): "
                     f"{', '.join(summary['failed_meshes'])}")
    table = "".join(f"| {c} | {v:.3f} |\n" for c, v in summary["per_class"].items())
    return "\n".join(lines) + "\n\n| class | AP |\n|---|---|\n" + table
