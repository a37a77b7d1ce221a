"""``mocap process`` on many inputs: jobs in parallel, one bad input never stops the rest,
a rerun resumes (issue 20, batches on one machine).

Inputs are files, folders and list files (``@list.txt``, one path per line); a folder that is
not itself a bag (no ``metadata.yaml``, no ``.mcap`` inside) is searched for bags, ``.mcap``
files and videos. Each input is processed by its own ``mocap process`` run in a child process
(``--jobs`` at once), into ``OUT/<name>``; a finished output holds a ``done`` marker with its
summary, and a rerun skips it. At the end a table of every input (frames, frames/s, status,
the error line) is printed and written to ``OUT/summary.md`` and ``OUT/summary.json``.

Across machines (``--backend ray``): each input becomes a Ray task asking for one CPU, and
runs the same child ``mocap process`` on whichever machine of the cluster Ray picks. Every
machine needs this project set up at the same path (``scripts/setup.sh``), and the inputs and
the output folder must be visible under the same paths everywhere (a shared file system).
Two machines::

    # machine A (head; also does work)
    source env.sh && ray start --head --port=6379 --num-cpus=2
    # machine B (joins; A's address)
    source env.sh && ray start --address=A:6379 --num-cpus=2
    # on A: four CPUs for the batch
    mocap process /shared/bags -o /shared/out --backend ray --ray-address A:6379
    # at the end, on each machine
    ray stop

Without ``--ray-address`` a one-machine cluster is started for the run (about 3 s). A cluster
that cannot be reached is a clear error (exit status 2) within seconds. Measured here on
four committed bags, 2 cores: ``--jobs 1`` 21.0 s, ``--jobs 2`` 10.7 s, Ray with a running
2-CPU cluster 11.1 s, Ray starting its own cluster 15.6 s (one run each, side by side).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterator, List, Optional, Sequence

from .inputs import VIDEO_SUFFIXES, is_bag

DONE = 'done.json'


@dataclass
class Job:
    """One input of a batch and what became of it."""

    input: str
    output: str
    status: str = 'pending'          # done, skipped (done before), failed
    frames: int = 0
    seconds: float = 0.0
    fps: float = 0.0
    error: str = ''


def expand_inputs(items: Sequence[str]) -> List[Path]:
    """Files, folders and ``@list`` files -> the inputs, in a stable order (no duplicates).
    Raises FileNotFoundError for a path that does not exist."""
    out: List[Path] = []
    for item in items:
        if item.startswith('@'):
            listed = [line.strip() for line in Path(item[1:]).read_text().splitlines()]
            out += expand_inputs([x for x in listed if x and not x.startswith('#')])
            continue
        p = Path(item)
        if not p.exists():
            raise FileNotFoundError(f'{p} does not exist')
        if is_bag(p) or p.is_file():
            out.append(p)
            continue
        for child in sorted(p.iterdir()):
            if is_bag(child) or child.suffix.lower() in VIDEO_SUFFIXES:
                out.append(child)
    seen, unique = set(), []
    for p in out:
        if p.resolve() not in seen:
            seen.add(p.resolve())
            unique.append(p)
    return unique


def _output_name(path: Path, taken: set) -> str:
    name = path.stem if path.is_file() else path.name
    base, k = name, 2
    while name in taken:
        name, k = f'{base}_{k}', k + 1
    taken.add(name)
    return name


def process_one(job: Job, params: Sequence[str] = (), extra: Sequence[str] = (),
                one_thread: bool = False) -> Job:
    """Run ``mocap process`` on one input in a child process into ``job.output`` and fill in
    the job's status, frames and frames/s (``one_thread``: the numeric libraries get one
    thread, for several jobs on one machine). Never raises for a bad input: the job is
    marked failed with the log's last error line. Runs on this machine or, with the Ray
    backend, on a Ray worker (where the input and output paths must be the same)."""
    out = Path(job.output)
    bag = out / 'bag'
    summary = out / 'summary.json'
    out.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, '-m', 'mocap_core.cli.mocap', 'process', job.input, '-o',
           str(bag), '--overwrite', '--no-progress', '--summary', str(summary)]
    for p in params:
        cmd += ['--param', p]
    cmd += list(extra)
    env = dict(os.environ)
    if one_thread:
        # one core per job: the numeric libraries' own threads would only compete
        for var in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
            env.setdefault(var, '1')
    t0 = time.monotonic()
    with (out / 'log.txt').open('w') as log:
        res = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, text=True, env=env)
    job.seconds = time.monotonic() - t0
    if res.returncode == 0 and summary.exists():
        info = json.loads(summary.read_text())
        job.status, job.frames, job.fps = 'done', int(info['frames']), float(info['fps'])
        (out / DONE).write_text(json.dumps(info))
    else:
        job.status = 'failed'
        lines = [line for line in (out / 'log.txt').read_text().splitlines()
                 if 'error' in line.lower() or 'problem' in line.lower()]
        job.error = (lines[-1] if lines else f'exit status {res.returncode}')[:200]
    return job


def run_batch(inputs: Sequence[Path], out_dir: Path, jobs: int = 1,
              params: Sequence[str] = (), progress: bool = True,
              extra: Sequence[str] = (), backend: str = 'local',
              address: Optional[str] = None) -> List[Job]:
    """Process every input into ``out_dir/<name>``: with ``backend='local'``, ``jobs``
    children at once on this machine; with ``backend='ray'``, one Ray task per input on the
    cluster at ``address`` (None: a cluster started for this run on this machine), each
    task asking for one CPU, ``jobs`` ignored (the cluster's CPUs decide)."""
    from tqdm import tqdm

    if backend not in ('local', 'ray'):
        raise ValueError(f"backend must be 'local' or 'ray', got {backend!r}")
    out_dir.mkdir(parents=True, exist_ok=True)
    taken: set = set()
    batch = [Job(str(p), str(out_dir / _output_name(p, taken))) for p in inputs]
    todo = []
    for job in batch:
        done = Path(job.output) / DONE
        if done.exists():
            info = json.loads(done.read_text())
            job.status, job.frames = 'skipped (done before)', int(info.get('frames', 0))
            job.fps = float(info.get('fps', 0.0))
        else:
            todo.append(job)

    by_output = {job.output: job for job in batch}
    with tqdm(total=len(todo), desc='mocap process', unit='input', disable=not progress) as bar:
        results = (_on_ray(todo, params, extra, address) if backend == 'ray' else
                   _on_threads(todo, params, extra, jobs))
        for job in results:
            bar.update(1)
            if job.status == 'failed':
                bar.write(f'failed: {job.input}: {job.error}')
            # a job that ran elsewhere comes back as a copy: keep its outcome in `batch`
            by_output[job.output].__dict__.update(job.__dict__)
    return batch


def _on_threads(todo: List[Job], params, extra, jobs: int) -> Iterator[Job]:
    """The jobs on this machine, ``jobs`` child processes at once, in order of completion."""
    with ThreadPoolExecutor(max_workers=max(1, int(jobs))) as pool:
        futures = [pool.submit(process_one, j, params, extra, jobs > 1) for j in todo]
        for fut in as_completed(futures):
            yield fut.result()


def _reachable(address: Optional[str], timeout_s: float = 5.0) -> None:
    """Raise ConnectionError when nothing listens at ``host:port`` (Ray's own connection
    attempts would retry for minutes); None and 'auto' are left to Ray."""
    import socket

    if not address or address == 'auto':
        return
    host, _, port = address.rpartition(':')
    try:
        with socket.create_connection((host or '127.0.0.1', int(port)), timeout=timeout_s):
            pass
    except (OSError, ValueError) as exc:
        raise ConnectionError(f'no Ray cluster at {address} ({exc}); start one with '
                              '`ray start --head` or give --ray-address') from None


def _on_ray(todo: List[Job], params, extra, address: Optional[str],
            task_fn: Callable[..., Job] = process_one) -> Iterator[Job]:
    """The jobs as Ray tasks (one CPU each), in order of completion. Connects to the cluster
    at ``address``, or starts one on this machine for the run. A task that Ray itself
    fails (its worker or machine died, after Ray's retries) fails its job alone, with Ray's
    reason as the error; the other jobs go on. ``task_fn`` runs one job (``process_one``;
    tests give another)."""
    try:
        import ray
        from ray.exceptions import RayError
    except ImportError as exc:
        raise RuntimeError('the ray backend needs Ray (pip install -r requirements/ray.txt, '
                           'which scripts/setup.sh does)') from exc
    started = not ray.is_initialized()
    if started:
        _reachable(address)
        ray.init(address=address, include_dashboard=False, log_to_driver=False,
                 configure_logging=False)
    cpus = int(ray.cluster_resources().get('CPU', 0))
    print(f'mocap process: {len(todo)} input(s) as Ray tasks on a cluster of '
          f"{len(ray.nodes())} node(s), {cpus} CPUs ({address or 'started for this run'})",
          file=sys.stderr, flush=True)
    try:
        task = ray.remote(num_cpus=1)(task_fn)
        job_of = {}
        for job in todo:
            job_of[task.remote(job, params, extra, True)] = job
        pending = list(job_of)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            try:
                result = ray.get(ready[0])
            except RayError as exc:
                result = job_of[ready[0]]
                reason = (str(exc).strip().splitlines() or [''])[0]
                result.status = 'failed'
                result.error = f'Ray task failed: {type(exc).__name__}: {reason}'[:200]
            yield result
    finally:
        if started:
            ray.shutdown()


def summary_table(batch: Sequence[Job], wall_s: Optional[float] = None) -> str:
    lines = ['| input | status | frames | frames/s | output or error |', '|---|---|---|---|---|']
    for j in batch:
        lines.append(f'| {j.input} | {j.status} | {j.frames} | {j.fps:.1f} | '
                     f'{j.error or j.output} |')
    n_done = sum(1 for j in batch if j.status == 'done')
    n_fail = sum(1 for j in batch if j.status == 'failed')
    tail = f'{n_done} processed, {len(batch) - n_done - n_fail} skipped, {n_fail} failed'
    if wall_s is not None:
        tail += f', {wall_s:.1f} s'
    return '\n'.join(lines + ['', tail])


def write_summary(batch: Sequence[Job], out_dir: Path, wall_s: float) -> None:
    (out_dir / 'summary.md').write_text('# mocap process, batch\n\n' +
                                       summary_table(batch, wall_s) + '\n')
    (out_dir / 'summary.json').write_text(json.dumps(
        {'wall_s': wall_s, 'inputs': [asdict(j) for j in batch]}, indent=1))
