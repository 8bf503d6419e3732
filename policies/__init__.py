"""Policy-search algorithms (GAE, PPO, TRPO), training and evaluation."""
