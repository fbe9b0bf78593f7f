"""BVH for Scratch ray tracers: build (binned SAH, optional optimiser), encode (binary / wide4 /
quantised flat lists), traverse (reference walks that read the lists like the Scratch script),
verify (rays, Embree and brute-force comparisons), stage (the ``bvh`` pipeline stage).
Formats: docs/formats-bvh.md."""
