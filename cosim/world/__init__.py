"""Stage 3, the world the robot drives in: obstacle shapes, exact distances, the known map's
checks, and the lidar that sees the true world."""
