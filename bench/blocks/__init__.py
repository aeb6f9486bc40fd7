"""Suites about the blocks of flowtact.blocks, one folder per room (signal, spiking, teleop)."""
