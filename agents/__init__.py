"""agents: policies (PD, random, stable-baselines3) and the model-based RL loop."""
