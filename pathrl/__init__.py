"""pathrl: learning time-optimized robot path tracking (PPO) with TOPP-RA as the physical reference."""

__version__ = "0.1.0"
