"""The reinforcement-learning side: the Gymnasium environment, policies, training, and the
rl planner.
"""
