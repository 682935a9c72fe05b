"""The physics of the cloth: spring and external forces (:mod:`.forces`), the stability analysis of
a material and step (:mod:`.stability`), triangle meshes and their springs (:mod:`.mesh`) and the
energy balance that tells a chattering run from a physical one (:mod:`.energy_balance`)."""
