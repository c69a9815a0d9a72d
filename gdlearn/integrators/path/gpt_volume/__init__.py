"""gpt's lockstep base/offset kernels with media and null interfaces."""
