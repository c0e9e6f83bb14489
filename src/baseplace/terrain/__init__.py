"""Terrain: point-cloud input, and (to come) voxel and height maps, segmentation, region graphs."""

from baseplace.terrain.io import Cloud, load_cloud, load_transform, save_cloud, up_vector_transform

__all__ = ["Cloud", "load_cloud", "load_transform", "save_cloud", "up_vector_transform"]
