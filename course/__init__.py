"""A differentiable renderer written from scratch in torch, and the course built on it."""
