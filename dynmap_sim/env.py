"""The Gymnasium env (a thin shell over world, robot and sensors)."""
