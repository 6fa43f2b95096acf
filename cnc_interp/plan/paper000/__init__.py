"""Paper 000 (de Santiago-Perez et al. 2010): constant and variable feedrate planners.

- ``curvature``: curvature peaks per segment (Eq. 3 for planar segments, numerical for
  general paths) and the per-segment joint-space geometry the limits need.
- ``limits``: tangential feed / acceleration / jerk limits derived from per-axis limits.
- ``profile``: the jerk-bounded polynomial feed transition (reference 22) and
  ``SegmentProfiles``, the per-segment profile data kept for the FPGA stage.
- ``constant`` / ``variable``: the planners (``plan_path_constant``, ``plan_path_variable``).

Nothing heavy is imported here; import the submodules you need.
"""
