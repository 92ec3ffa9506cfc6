"""scanplan: robotic laser-profilometer scan planning (Boustrophedon + PPO)."""

__version__ = "0.1.0"
