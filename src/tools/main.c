/* gen3d: the command-line entry point. Dispatches `gen3d <command> ...` to the command table
 * generated from src/tools/cmd_*.c. */
#include "cli.h"

#include <stdio.h>
#include <string.h>

#include "commands.inc"

static void print_usage(FILE *out)
{
    fprintf(out,
            "gen3d %s - explorable 3D Gaussian-splat scenes from one RGB-D image, RGB image or text prompt\n\n"
            "usage: gen3d <command> [options]\n"
            "       gen3d <command> --help\n"
            "       gen3d --version\n\n"
            "commands:\n",
            G3D_VERSION_STRING);
    for (int i = 0; g3d_commands[i]; i++)
        fprintf(out, "  %-10s %s\n", g3d_commands[i]->name, g3d_commands[i]->summary);
    fprintf(out,
            "\ncommon options: -o/--output PATH, -s/--seed N, -t/--threads N, -q/--quiet, -v/--verbose\n"
            "Results are printed on stdout, progress and messages on stderr. Exit status: 0 success,\n"
            "1 failure (bad input, I/O error), 2 usage error, 130 interrupted.\n");
}

int main(int argc, char **argv)
{
    g3d_process_setup(argv);
    if (argc < 2) {
        print_usage(stderr);
        return G3D_EXIT_USAGE;
    }
    if (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help") || !strcmp(argv[1], "help")) {
        print_usage(stdout);
        return G3D_EXIT_OK;
    }
    if (!strcmp(argv[1], "--version") || !strcmp(argv[1], "version")) {
        printf("gen3d %s\n", G3D_VERSION_STRING);
        return G3D_EXIT_OK;
    }
    for (int i = 0; g3d_commands[i]; i++)
        if (!strcmp(argv[1], g3d_commands[i]->name)) return g3d_commands[i]->run(argc - 1, argv + 1);
    return g3d_cli_errorf(G3D_EXIT_USAGE, "unknown command '%s' (see gen3d --help)", argv[1]);
}
