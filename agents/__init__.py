"""bboxtune tuners: stable-baselines3 agents and non-learned baselines."""
