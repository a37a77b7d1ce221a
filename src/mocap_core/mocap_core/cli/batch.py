"""``mocap process`` on many inputs: jobs in parallel, one bad input never stops the rest,
a rerun resumes (issue 20, batches on one machine).

Inputs are files, folders and list files (``@list.txt``, one path per line); a folder that is
not itself a bag (no ``metadata.yaml``, no ``.mcap`` inside) is searched for bags, ``.mcap``
files and videos. Each input is processed by its own ``mocap process`` run in a child process
(``--jobs`` at once), into ``OUT/<name>``; a finished output holds a ``done`` marker with its
summary, and a rerun skips it. At the end a table of every input (frames, frames/s, status,
the error line) is printed and written to ``OUT/summary.md`` and ``OUT/summary.json``.
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
from typing import List, Optional, Sequence

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


def run_batch(inputs: Sequence[Path], out_dir: Path, jobs: int = 1,
              params: Sequence[str] = (), progress: bool = True,
              extra: Sequence[str] = ()) -> List[Job]:
    """Process every input into ``out_dir/<name>`` with ``jobs`` children at once."""
    from tqdm import tqdm

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

    def one(job: Job) -> Job:
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
        if jobs > 1:
            # one core per job: the numeric libraries' own threads would only compete
            for var in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
                env.setdefault(var, '1')
        t0 = time.monotonic()
        with (out / 'log.txt').open('w') as log:
            res = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, text=True,
                                 env=env)
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

    with tqdm(total=len(todo), desc='mocap process', unit='input', disable=not progress) as bar:
        with ThreadPoolExecutor(max_workers=max(1, int(jobs))) as pool:
            for fut in as_completed([pool.submit(one, j) for j in todo]):
                job = fut.result()
                bar.update(1)
                if job.status == 'failed':
                    bar.write(f'failed: {job.input}: {job.error}')
    return batch


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
