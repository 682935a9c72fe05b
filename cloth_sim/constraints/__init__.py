"""What holds the cloth besides its springs: the strain limit (Provot's passes and the projection,
:mod:`.strain_limit`, its kernels :mod:`.strain_limit_kernels`, :mod:`.strain_projection`) and the
grippers (:mod:`.grippers`)."""
