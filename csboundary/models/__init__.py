"""The networks (paper IV-B, IV-D): the FPN keypoint/segmentation model and AfANet."""
