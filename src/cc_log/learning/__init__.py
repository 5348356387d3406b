"""The classifier's model, training, online learning, drift and the physics envelope. Imports
``base`` and ``features``."""
