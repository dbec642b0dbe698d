"""Fit, replay and step the estimator from Python: the README's example.

    python python/examples/quickstart.py [DATASET] [MODEL_FOLDER]
"""

import sys

import numpy as np

import rollest

data = rollest.load_dataset(sys.argv[1] if len(sys.argv) > 1 else "out/campaign")
model = rollest.fit(data, sys.argv[2] if len(sys.argv) > 2 else "out/py-model")  # as `host-tools fit`
for row in model.report["heldout"]["per_alpha"]:
    print(f"alpha {row['alpha_deg']:4.1f} deg: held-out RMS of C_l {row['coupled_rms'] or float('nan'):.2e}")

run = next(run for run in data.runs if run.kind == "roll+actuation")
out = rollest.Estimator(model).run(run)  # every stage, bit for bit as `host-tools replay`
start = rollest.heldout_start(len(run))
error = out["cl_est"][start:] - run.arrays["cl"][start:]
print(f"{run.file}: held-out RMS {np.sqrt(np.mean(error**2)):.2e}, flagged steps {np.count_nonzero(out['health_flags'])}")

estimator = rollest.Estimator(model)  # one sample at a time, as in a control loop
sample = estimator.step(phi_deg=5.0, alpha_deg=20.0, cmu_port=0.0, cmu_stbd=0.0, cp=[-0.3] * 12)
print(f"C_l = {sample['cl_est']:+.4f} (health flags {sample['health_flags']:#06x})")
