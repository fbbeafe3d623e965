"""What a run is asked to do: the scene, its sections, presets and TOML in/out, and the rods and
gas it describes (numpy; no Taichi, no engine).

:class:`~dem_taichi.scene.config.Scene` and :func:`~dem_taichi.scene.config.load_scene`
(:mod:`~dem_taichi.scene.config`), the section base (:mod:`~dem_taichi.scene.base`), the core
sections (:mod:`~dem_taichi.scene.sections`; those of the interactions in
:mod:`~dem_taichi.scene.interaction_sections`), the ``[protocol]`` and ``[probing]`` sections
(:mod:`~dem_taichi.scene.protocol_sections`, :mod:`~dem_taichi.scene.probing_sections`), presets
and command-line options (:mod:`~dem_taichi.scene.presets`, :mod:`~dem_taichi.scene.options`),
and the rod geometry and starting gas a scene resolves to (:mod:`~dem_taichi.scene.geometry`,
:mod:`~dem_taichi.scene.gas_placement`). Imports only :mod:`dem_taichi.physics` below it.
"""

from dem_taichi._moved import forward_attributes

#: the names of the former module ``dem_taichi.scene`` (now :mod:`dem_taichi.scene.geometry`)
__getattr__ = forward_attributes(__name__)
