# The workflow on a Slurm cluster (workflow/profiles/slurm, mk/py.mk): Debian's Slurm 22.05
# (controller, node daemon, client commands) and munge, brought up as a one-node cluster by
# scripts/slurm_cluster.sh for the test, and Snakemake's Slurm executor plugin (its jobstep
# plugin comes with it). Pinned: the test relies on the plugin's squeue status command and
# --slurm-no-account, checked with these versions.
need_apt slurmctld slurmd slurm-client munge
need_pip snakemake-executor-plugin-slurm==2.8.0 snakemake-executor-plugin-slurm-jobstep==0.6.1
