"""mcgnode from Python: the trajectories of ParticleState bags as numpy arrays,
models (files, ``still``, ``truth:<system>``) rolled out as ``mcgnode rollout``
rolls them out, bit for bit, and training as ``mcgnode train`` trains.

>>> import mcgnode
>>> tr = mcgnode.read_bag("bags/spring5-sample.mcap")[0]
>>> out = mcgnode.load_model("truth:spring").rollout(tr, 100)
>>> out["positions"].shape
(101, 5, 2)
"""

from ._mcgnode import Error, Model, __version__, load_model, read_bag, train

__all__ = ["Error", "Model", "__version__", "load_model", "read_bag", "train"]
