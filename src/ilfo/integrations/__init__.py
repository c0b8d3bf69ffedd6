"""ilfo's rewards in other people's RL code: ``sb3`` (Stable-Baselines3 and sbx: a replay
buffer that relabels each episode when it ends; ``pip install -e ".[sb3]"``). Each module is
imported on its own, so that ilfo needs none of these libraries."""
