"""Evaluation of policies and controllers: rollouts, campaigns, sweeps, Ray, reachability and the
paper's Table 7. Nothing here imports torch to fly a controller."""
