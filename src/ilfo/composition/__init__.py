"""Learners that are an agent and a learned reward trained together: an off-policy agent on a
reward learned beside it (``learned.with_learned_reward``: GAIfO/DACfO, f-IRL, OOPS_adv) and
OPOLO, whose policy update also reads its discriminator. The one layer where agents and rewards
meet below the registry (``ilfo.algos``): neither ``ilfo.agents`` nor ``ilfo.rewards`` imports
the other."""
