"""Physics: the decay equation, hull configurations, simulation of decays."""
