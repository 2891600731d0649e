#pragma once
// Uniform command-line behaviour for every executable: --help exits 0 and shows every option's
// default, a bad argument prints one line naming the value and what was expected and exits 2,
// anything else exits 1 (errors.hpp). Only the executables' option parsing includes it.
//
// CLI11 does the parsing, the validation and the messages, behind a compile firewall: it is
// header-only, and its header alone cost 8.5 s of -O3 compilation in every translation unit that
// included it (its namespace-scope validators and their lambdas are compiled in each one), a
// quarter of the main job's build for seven executables. Only common/src/cli.cpp includes it;
// these classes are thin handles on CLI11's own App, Option and Validator, with the subset of
// their API the executables use, under the same names.
#include "sphperf/errors.hpp"

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace CLI {
class App;
class Option;
class Validator;
} // namespace CLI

namespace sphperf::cli {

// A CLI11 validator (check of an option's value); `a & b` passes when both pass.
class Validator {
public:
    explicit Validator(std::shared_ptr<const CLI::Validator> v) : v_(std::move(v)) {}
    Validator operator&(const Validator &other) const;
    const CLI::Validator &get() const { return *v_; }

private:
    std::shared_ptr<const CLI::Validator> v_;
};

// CLI11's validators of the same names.
Validator Range(int min, int max);
Validator Range(std::int64_t min, std::int64_t max);
Validator Range(double min, double max);
Validator IsMember(std::vector<std::string> choices);
extern const Validator ExistingFile;
extern const Validator ExistingDirectory;

// CLI11's number validators let NaN and inf through: combine them with this one.
extern const Validator Finite;
// A finite number above (or at least) a bound, with a one-line message naming the value.
Validator finite_above(double bound, bool or_equal);
extern const Validator FinitePositive;
extern const Validator FiniteNonNegative;

// An option of an App (a handle on CLI::Option); the App owns it.
class Option {
public:
    explicit Option(CLI::Option *o) : o_(o) {}
    Option *check(const Validator &v);
    Option *required();
    Option *delimiter(char c);
    Option *capture_default_str();
    Option *needs(Option *other);
    Option *excludes(Option *other);
    // How many times it was given on the command line (0: absent).
    std::size_t count() const;

private:
    CLI::Option *o_;
};

// A command line, or a subcommand of one (a handle on CLI::App).
class App {
public:
    explicit App(std::string description);
    ~App();
    App(const App &) = delete;
    App &operator=(const App &) = delete;

    // Binds `value`; its type is one of those instantiated in cli.cpp.
    template <class T>
    Option *add_option(const std::string &name, T &value, const std::string &description = "");
    template <class T>
    Option *add_option_function(const std::string &name, std::function<void(const T &)> f,
                                const std::string &description = "");
    Option *add_flag(const std::string &name, bool &value, const std::string &description = "");
    App *add_subcommand(const std::string &name, const std::string &description);

    void require_subcommand(int n);
    // Width of the option column in --help.
    void column_width(std::size_t width);
    // Every option's default shown in --help, also of those added later.
    void always_capture_default();
    // How many times option `name` was given.
    std::size_t count(const std::string &name) const;
    // Whether this subcommand was given.
    bool parsed() const;

    // Parses argv; on --help prints and requests exit 0, on a parse error throws UsageError.
    void parse(int argc, char **argv);

private:
    explicit App(CLI::App *sub); // a subcommand
    Option *own(CLI::Option *o);

    std::unique_ptr<CLI::App> owned_; // null for a subcommand (its parent's CLI::App owns it)
    CLI::App *app_;
    std::deque<Option> options_;
    std::deque<std::unique_ptr<App>> subcommands_;
};

} // namespace sphperf::cli

namespace sphperf {
// The executables' spelling: parse_cli(app, argc, argv) and the validators unqualified.
inline void parse_cli(cli::App &app, int argc, char **argv) {
    app.parse(argc, argv);
}
using cli::Finite;
using cli::finite_above;
using cli::FiniteNonNegative;
using cli::FinitePositive;
} // namespace sphperf
