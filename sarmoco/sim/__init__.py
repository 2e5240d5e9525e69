"""Simulated hardware: scenarios, trajectories, INS errors, echoes, wire emitters."""
