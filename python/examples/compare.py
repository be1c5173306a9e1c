# Position MSE of each model's rollout over a bag's first trajectory.
import sys
import numpy as np
import mcgnode
tr = mcgnode.read_bag(sys.argv[1])[0]
steps = (len(tr["stamps"]) - 1) * tr["save_every"]
for ref in sys.argv[2:]:
    out = mcgnode.load_model(ref).rollout(tr, steps, every=tr["save_every"])
    mse = np.mean((out["positions"] - tr["positions"]) ** 2)
    print(f"{ref}: position MSE {mse:.3e}")
