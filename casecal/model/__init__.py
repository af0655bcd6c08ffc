"""The robot model: parameters, conventions (DH, modified DH), frames, the symbolic chain
and its compiled kernels, the catalog and robot files. Everything above it (data,
identification, design, studies) imports from here; nothing here imports from them."""
