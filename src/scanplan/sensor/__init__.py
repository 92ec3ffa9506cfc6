"""The line profilometer simulated: profiles, point clouds, perturbed parts and defects."""
