"""The software-in-the-loop simulator: the world on the far side of the serial link. Nothing here
ships to the bedside; the shipped path is ``runtime`` (and the ``link`` protocol it speaks).

It simulates seeded patients (the seed paper's nonlinear model by default, or a plugin), the
infusion pump, the MAP monitor, scenarios with disturbances and injected faults, and cohort trials.
What a user runs: ``pressor trial`` (in-process cohort trial, :mod:`pressor.hil_sim.cli`), ``pressor sil``
(this device against the real runtime over a pty; :mod:`pressor.sil`) and ``pressor device`` (the
device process alone, :mod:`pressor.hil_sim.devices.device`). Where each part is, bottom to top
(tests/test_layers.py's ``SIM_ALLOWED``):

- :mod:`pressor.hil_sim.patients`: the patient models, the ``PatientModel`` plugin protocol, seeded cohorts;
- :mod:`pressor.hil_sim.devices`: pump and monitor, and the device process over the link (above the world);
- :mod:`pressor.hil_sim.native`: compiled twins of pure arithmetic that trials use where a C compiler works
  (the LPV step, the estimator, the paper patient; the same bytes as the Python,
  ``PRESSOR_NATIVE=off`` to run without);
- :mod:`pressor.hil_sim.scenarios`: the named scenario TOMLs, their loader, disturbances and faults;
- :mod:`pressor.hil_sim.world`: the one simulated world, stepped tick by tick (patient + pump + monitor);
- :mod:`pressor.hil_sim.episode`: one patient's run in process (world + the runtime's closed-loop core);
- :mod:`pressor.hil_sim.reach`: what the dose limits can hold a patient at for the scenario's hour;
- :mod:`pressor.hil_sim.trials`: cohort trials, paired comparisons, reports; :mod:`pressor.hil_sim.cli` their commands.

May import ``contracts``, ``baselines``, ``link`` and ``runtime`` (its closed-loop core, so the
in-process run is the shipped loop); never imported by them.
"""
