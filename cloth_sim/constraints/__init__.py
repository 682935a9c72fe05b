"""What holds the cloth besides its springs: the strain limit (Provot's passes and the projection,
:mod:`.strain_limit`, :mod:`.strain_projection`) and the grippers (:mod:`.grippers`)."""
