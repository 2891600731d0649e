// The one translation unit that compiles CLI11 (cli.hpp says why).
#include "sphperf/cli.hpp"

#include <CLI/CLI.hpp>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <optional>

namespace sphperf::cli {

namespace {
Validator wrap(CLI::Validator v) {
    return Validator(std::make_shared<const CLI::Validator>(v));
}
} // namespace

Validator Validator::operator&(const Validator &other) const {
    return wrap(get() & other.get());
}

Validator Range(int min, int max) {
    return wrap(CLI::Range(min, max));
}
Validator Range(std::int64_t min, std::int64_t max) {
    return wrap(CLI::Range(min, max));
}
Validator Range(double min, double max) {
    return wrap(CLI::Range(min, max));
}
Validator IsMember(std::vector<std::string> choices) {
    return wrap(CLI::IsMember(std::move(choices)));
}
const Validator ExistingFile = wrap(CLI::ExistingFile);
const Validator ExistingDirectory = wrap(CLI::ExistingDirectory);

const Validator Finite = wrap(CLI::Validator(
    [](const std::string &s) {
        try {
            const double v = std::stod(s);
            return std::isfinite(v) ? std::string() : "value " + s + " is not a finite number";
        } catch (const std::exception &) {
            return "value " + s + " is not a number";
        }
    },
    "FINITE"));

Validator finite_above(double bound, bool or_equal) {
    const std::string want = std::string(or_equal ? ">= " : "> ") + CLI::detail::to_string(bound);
    return wrap(CLI::Validator(
        [bound, or_equal, want](const std::string &s) {
            try {
                const double v = std::stod(s);
                if (std::isfinite(v) && (or_equal ? v >= bound : v > bound))
                    return std::string();
            } catch (const std::exception &) {
            }
            return "value " + s + " is not a finite number " + want;
        },
        "FINITE " + want));
}
const Validator FinitePositive = finite_above(0.0, false);
const Validator FiniteNonNegative = finite_above(0.0, true);

Option *Option::check(const Validator &v) {
    o_->check(v.get());
    return this;
}
Option *Option::required() {
    o_->required();
    return this;
}
Option *Option::delimiter(char c) {
    o_->delimiter(c);
    return this;
}
Option *Option::capture_default_str() {
    o_->capture_default_str();
    return this;
}
Option *Option::needs(Option *other) {
    o_->needs(other->o_);
    return this;
}
Option *Option::excludes(Option *other) {
    o_->excludes(other->o_);
    return this;
}
std::size_t Option::count() const {
    return o_->count();
}

App::App(std::string description)
    : owned_(std::make_unique<CLI::App>(std::move(description))), app_(owned_.get()) {}
App::App(CLI::App *sub) : app_(sub) {}
App::~App() = default;

Option *App::own(CLI::Option *o) {
    return &options_.emplace_back(o);
}

template <class T>
Option *App::add_option(const std::string &name, T &value, const std::string &description) {
    return own(app_->add_option(name, value, description));
}
template <class T>
Option *App::add_option_function(const std::string &name, std::function<void(const T &)> f,
                                 const std::string &description) {
    return own(app_->add_option_function<T>(name, std::move(f), description));
}
Option *App::add_flag(const std::string &name, bool &value, const std::string &description) {
    return own(app_->add_flag(name, value, description));
}
App *App::add_subcommand(const std::string &name, const std::string &description) {
    return subcommands_.emplace_back(new App(app_->add_subcommand(name, description))).get();
}

void App::require_subcommand(int n) {
    app_->require_subcommand(n);
}
void App::column_width(std::size_t width) {
    app_->get_formatter()->column_width(width);
}
void App::always_capture_default() {
    app_->option_defaults()->always_capture_default();
}
std::size_t App::count(const std::string &name) const {
    return app_->count(name);
}
bool App::parsed() const {
    return app_->parsed();
}

void App::parse(int argc, char **argv) {
    // --help shows every option's default: the values bound before parsing.
    for (auto *opt : app_->get_options())
        opt->capture_default_str();
    try {
        app_->parse(argc, argv);
    } catch (const CLI::CallForHelp &) {
        std::cout << app_->help();
        throw ExitRequest{0};
    } catch (const CLI::CallForAllHelp &) {
        std::cout << app_->help("", CLI::AppFormatMode::All);
        throw ExitRequest{0};
    } catch (const CLI::ParseError &e) {
        std::string msg = e.what();
        for (auto &c : msg)
            if (c == '\n')
                c = ' ';
        throw UsageError(msg + " (see --help)");
    }
}

// The option types the executables bind (another one is a link error naming it).
using Path = std::filesystem::path;
template Option *App::add_option<int>(const std::string &, int &, const std::string &);
template Option *App::add_option<long>(const std::string &, long &, const std::string &);
template Option *App::add_option<unsigned long>(const std::string &, unsigned long &,
                                                const std::string &);
template Option *App::add_option<double>(const std::string &, double &, const std::string &);
template Option *App::add_option<std::string>(const std::string &, std::string &,
                                              const std::string &);
template Option *App::add_option<Path>(const std::string &, Path &, const std::string &);
template Option *App::add_option<std::optional<Path>>(const std::string &, std::optional<Path> &,
                                                      const std::string &);
template Option *App::add_option<std::optional<double>>(const std::string &,
                                                        std::optional<double> &,
                                                        const std::string &);
template Option *App::add_option<std::optional<int>>(const std::string &, std::optional<int> &,
                                                     const std::string &);
template Option *App::add_option<std::optional<long>>(const std::string &, std::optional<long> &,
                                                      const std::string &);
template Option *App::add_option<std::vector<int>>(const std::string &, std::vector<int> &,
                                                   const std::string &);
template Option *App::add_option<std::vector<long>>(const std::string &, std::vector<long> &,
                                                    const std::string &);
template Option *App::add_option<std::vector<double>>(const std::string &, std::vector<double> &,
                                                      const std::string &);
template Option *App::add_option<std::vector<std::string>>(const std::string &,
                                                           std::vector<std::string> &,
                                                           const std::string &);
template Option *App::add_option<std::vector<Path>>(const std::string &, std::vector<Path> &,
                                                    const std::string &);
template Option *App::add_option_function<double>(const std::string &,
                                                  std::function<void(const double &)>,
                                                  const std::string &);

} // namespace sphperf::cli
