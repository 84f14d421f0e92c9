// The `corofem` command (placeholder until the CLI lands).
#include <cstdio>
int main() { std::puts("corofem: CLI not written yet"); return 1; }
