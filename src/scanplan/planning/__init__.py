"""From a part to a trajectory: views, rasters, the pass step model, planners, the path."""
