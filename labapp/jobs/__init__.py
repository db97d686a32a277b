"""The jobs of the bench application, one module each, called by the `sfr` commands and the GUI alike.

=============================  ==============================================  ==========================
job                            function                                        `sfr` command
=============================  ==============================================  ==========================
analyse a run                  :func:`labapp.jobs.analyse.analyse_run`         ``analyze``
calibrate the bench            :func:`labapp.jobs.calibrate_bench.calibrate_series`  ``calibrate-bench``
record a calibration series    :func:`labapp.jobs.series.new_series`           ``calibrate-bench --record``
simulate                       :func:`labapp.jobs.simulate.simulate`           ``simulate``
Monte Carlo simulation         :func:`labapp.jobs.simulate_mc.simulate_mc_job`  ``simulate --model mc``
design                         :func:`labapp.jobs.design.design`               ``design``
start a run                    :func:`labapp.jobs.run.new_run`                 ``run``
resume an interrupted run      :func:`labapp.jobs.run.resume_run`              ``run --resume``
finalise an interrupted run    :func:`labapp.jobs.run.finalise`                (the GUI's Runs tab, Finalise)
verify a folder                :func:`labapp.jobs.verify.verify`               ``verify``
calibrate the simulation       :func:`labapp.jobs.calibrate_sim.calibrate_sim`  ``calibrate-sim``
evaluate the forward model     :func:`labapp.jobs.evaluate.evaluate_models`    ``evaluate``
compare release curves         :func:`labapp.jobs.compare.compare_curves`      ``compare``
compare replicate units        :func:`labapp.jobs.compare.compare_sets`        ``compare --test``
the demo                       :func:`labapp.jobs.demo.run_demo`               ``demo``
=============================  ==============================================  ==========================

Sweeps and batch reanalysis fan these jobs out on Dask (:mod:`labapp.scaleout`).

Each job checks its output path (:mod:`labapp.records.outpaths`) and its inputs before any work, raises
:class:`labapp.errors.UsageError` (or the package's own error) for bad input, and reports progress
through a plain callable. An acquisition (new or resumed run, calibration series) is a procedure the engine
walks; the job builds and checks it, the caller walks it with :class:`labapp.acquisition.engine.Engine`.
"""
