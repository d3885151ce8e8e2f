"""The application layer: scenes, sweeps, bench, reports, plots, the CLI and the demo.

The only part of flexctl that imports :mod:`controllers`; it holds no physics.

====================  ========================================================================
module                contents
====================  ========================================================================
``scenes``            scene TOML files parsed into validated ``Scene`` values, and run
``builtin_scenes``    the scene files shipped with the package
``sweep``             parameter sweeps on any executor, Pareto fronts
``sweep_store``       a sweep's finished tasks on disk (SQLite), task keys and seeds, resume
``sweep_runner``      running a sweep's tasks: failures recorded, lost workers retried
``task_fingerprint``  the SHA-256 of a task's code and inputs a store checks on resume
``bench``             speed-against-error benchmarks of variants, modes and integrators
``bench_plot``        the bench's speed-against-error figure
``bench_report``      the bench's CSV, Markdown pages and report.md
``report``            a run's summary, time series and figures written to disk
``runner``            one scene end to end: controller design, run, files moved in complete
``markdown``          the one Markdown-table renderer of the reports
``figures``           the bare matplotlib figure the plots start from
``plotting``          figures of responses, modes, frequencies, controller comparisons
``plotting_sweeps``   sweep curves and Pareto plots
``plotting_loops``    loop-shaping figures: Bode, Nyquist, margins
``cli``               the ``flexctl`` command: arguments, exit codes, held output
``demo``              ``flexctl demo``: built-in scenes, the papers' figures, comparisons
``run_cache``         the demo's runs remembered by their inputs and the code's version
====================  ========================================================================
"""
