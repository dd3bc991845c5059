"""Thin adapters that let code written for other ray casting libraries run on raycore.

- :mod:`raycore.integrations.trimesh`: ``RayMeshIntersector``, a drop-in for ``mesh.ray``.
- :mod:`raycore.integrations.open3d`: Open3D's ``RaycastingScene`` calls on a :class:`Scene`.

Each sits on :class:`raycore.Scene`'s public queries; none reaches into kernels.
"""
