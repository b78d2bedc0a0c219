"""Batch processing of whole asset libraries, on one machine or a Dask cluster. Qt-free.

``stylize3d batch METHOD INPUT... -o OUT_DIR`` (:mod:`app.cli.batch`) is a thin layer over
this package; the app's File > Batch… and scripts use the same API::

    from app import batch

    job = batch.build_job("cubic", ["--lambda", "0.4"])          # a sub-command and its flags
    job = batch.build_job("scene.s3d", panel="Cubic")              # a project's panel settings
    job = batch.job_from_settings("Cubic", params, options)       # a panel's own settings
    inputs = batch.collect_inputs(["library/", "extra/*.obj"], out_dir="out")
    summary = batch.run_batch(job, inputs, "out", workers=4,      # or scheduler="tcp://h:8786"
                              on_record=lambda rec, counts: ...,  # after every record
                              should_stop=lambda: cancelled)      # polled; True stops
    summary.exit_code, summary.counts(), summary.to_dict()

The pieces:

* :class:`Job` (:mod:`app.batch.jobs`): the recipe, its params and options, the blobs they
  refer to, built ONCE exactly as the one-mesh command builds them (its own flags; a project
  or panel-settings ``.json`` as METHOD for the settings; ``--params``); picklable, sent once
  to each worker. ``Job.key`` hashes all of it with the app's version.
* :func:`collect_inputs` / :func:`output_names` (:mod:`app.batch.inputs`): files, folders
  (recursively, mesh and project files), globs; results keep their file name below the
  inputs' deepest common folder.
* :func:`run_task` (:mod:`app.batch.worker`): one mesh in a worker process -- read (and clean
  with ``--clean``), run the recipe to its end, check, write atomically, return a record; a
  watchdog thread enforces the memory and time limits.
* :func:`run_batch` / :func:`plan` (:mod:`app.batch.driver`): the local process pool or the
  Dask executor, at most 2 x workers meshes in flight, the JSONL report (one line per input,
  fsync'ed), resuming, retries of meshes whose worker died.

A record (one report line): ``input``, ``output``, ``status`` ("done" / "failed" /
"skipped"), ``message`` (the plain reason of a failure or a skip), ``seconds``, ``key``
(SHA-256 of the input's bytes and the job), ``input_sha256``, ``output_sha256``,
``figures`` (vertex / face counts in and out, the recipe's outcome numbers -- iterations,
energy, ... -- and, for cubic, the mean L1 norm of the normals before and after),
``attempts``, ``retries``, ``worker`` (host:pid), ``task_id``, ``finished``, ``notes``
(what reading or cleaning the file said), ``limit`` ("memory" / "time" when a limit stopped
it).
"""

from __future__ import annotations

from app.batch.driver import (REPORT_NAME, BatchError, BatchSummary, default_memory_limit,
                              parse_size, plan, read_report, run_batch)
from app.batch.inputs import collect_inputs, collect_inputs_with_roots, output_names
from app.batch.jobs import (METHODS, PANEL_METHODS, BatchUsageError, Job, build_job,
                            job_from_settings, method_parser, parse_batch_args,
                            settings_note, write_panel_settings)
from app.batch.worker import EXIT_MEMORY, EXIT_TIME, run_task

__all__ = ["BatchError", "BatchSummary", "BatchUsageError", "EXIT_MEMORY", "EXIT_TIME", "Job",
           "METHODS", "PANEL_METHODS", "REPORT_NAME", "build_job", "collect_inputs",
           "collect_inputs_with_roots", "default_memory_limit", "job_from_settings",
           "method_parser", "output_names", "parse_batch_args", "parse_size", "plan",
           "read_report", "run_batch", "run_task", "settings_note", "write_panel_settings"]
