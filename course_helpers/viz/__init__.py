"""Pictures of the live system: the computation graph (static and live) and the course diagrams."""
