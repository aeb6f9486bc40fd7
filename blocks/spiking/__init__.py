"""Generic blocks on spikes: populations of neurons, rates, stimulation.

============ ================ ==========================================================
block        module           what
============ ================ ==========================================================
nlif         nlif             noisy leaky integrate-and-fire population, post-spike current
rate         rate             spikes → firing rate in bins
pulses       pulses           spikes → clamped stimulation pulses (amplitude, charge, rate)
synapse      synapse          spikes → currents: sparse weights (dense or seeded grid), exponential decay
naive_bayes  naive_bayes      spikes per window → posterior over classes and a decision
============ ================ ==========================================================

Helpers of ``naive_bayes``: ``window_features`` (counts / first-spike latencies per window, shared
with trainers), ``nb_model`` (fitting, the checked ``.npz`` model file, log-domain scoring).

Private kernels: ``_lif_kernels`` (numba LIF integrators and their numpy twins, in-kernel normal
generator), ``_spike_history`` (raised-cosine post-spike basis).
"""
