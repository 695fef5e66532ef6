"""Vectorized ports of OpenAI's Multi-Agent Particle Environments tasks."""
