"""Line segments and corners with calibrated covariances from 2D LiDAR scans."""
