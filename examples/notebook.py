# %% [markdown]
# # physgnn in a notebook
# The shipped model on an example scene: simulate the truth with pybullet, roll the learned
# simulator out from the same start, score it, film it and export it for ParaView.
# Open this percent-format script in Jupyter (jupytext) or VS Code, or run it with Python.
# Files go to `outputs/notebook/` under the working folder.

# %%
from pathlib import Path

import numpy as np

import physgnn.api as pg

OUT = Path("outputs/notebook")
FRAMES = 12  # a short film; the scene file asks for 60

# %% [markdown]
# ## A model and a scene
# `"pretrained"` is the shipped weights; a run folder (`outputs/runs/baseline/<time>`) works too.

# %%
model = pg.load_model("pretrained")
scene = pg.load_scene("throw")  # conf/scene/throw.yaml: a sphere thrown at a row of three
print(f"model with history H={model.H}; scene {scene.name}: {scene.n_spheres} spheres")

# %% [markdown]
# ## Truth, rollout, scores

# %%
truth = pg.simulate(scene, frames=FRAMES)
pred = pg.roll_out(model, truth)
scores = pg.score(pred, truth)
print({k: round(v, 4) for k, v in scores.items() if v is not None})

# %% [markdown]
# ## A scene from arrays
# Two spheres dropped side by side; out of the training ranges on purpose (a 3 m sphere), so
# `roll_out` warns with `pg.OutOfDistributionWarning`.

# %%
pos = np.array([[0.0, 0.0, 4.0], [8.0, 0.0, 6.0]])
drop = pg.scene_from_arrays(pos, radius=[0.5, 3.0], frames=FRAMES, name="two_drops")
drop_truth = pg.simulate(drop)
drop_pred = pg.roll_out(model, drop_truth)

# %% [markdown]
# ## Film and export

# %%
films = pg.animate(truth, pred, OUT / "throw", max_frames=4)
series = pg.export(pred, OUT / "throw_vtk", "vtk")  # open it in ParaView
print(films["gif"], series)
