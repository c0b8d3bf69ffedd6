"""The smallest run the loop's tests train: Hopper-v5 from the shipped scripted demos, 100-step
episodes, 200 random steps, an evaluation and a checkpoint every 200 steps, the fast preset."""

from ilfo.paths import bundled_demos

TINY_RUN = {
    "env": "Hopper-v5",
    "demos": str(bundled_demos("Hopper-v5-scripted")),
    "horizon": 100,
    "start_steps": 200,
    "eval_every": 200,
    "eval_episodes": 1,
    "checkpoint_every": 200,
    "preset": "fast",
    "replay_capacity": 5000,
}
