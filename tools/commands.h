// The subcommands of `octocosm`. Each Add*Command registers its subcommand,
// flags and help on the app; the callback runs the command and throws Error on
// failure (main() turns that into a message and an exit status).
#pragma once

namespace CLI {
class App;
}

namespace octocosm {

void AddIngestCommand(CLI::App& app);
void AddInfoCommand(CLI::App& app);
void AddVerifyCommand(CLI::App& app);
void AddSynthCommand(CLI::App& app);
void AddQueryCommand(CLI::App& app);
void AddFollowCommand(CLI::App& app);
void AddRenderCommand(CLI::App& app);
void AddViewCommand(CLI::App& app);
void AddServeCommand(CLI::App& app);

}  // namespace octocosm
