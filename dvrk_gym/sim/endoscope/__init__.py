"""What the stereo endoscope sees: the cameras (projection, rendering, triangulation, the baseline), detection of the
red marker and the grid circles on pixels, fragment detection, and the detections' pixel noise."""
