"""Agents: stable-baselines3 training, evaluation and the demo."""
