"""Reproduction of the paper's tables: which policy and baseline fill each row, and how the tables render."""
