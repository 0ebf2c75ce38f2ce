// artrace batch MANIFEST.json: a list of export jobs (recording, AR scene, output, frame range),
// run one after another or several at once, each as its own artrace export process. With --index
// it runs one entry: a cluster's array task (scripts/slurm/).
//
//   {"jobs": [{"recording": "fr1_desk", "scene": "desk.json", "output": "out/desk.mp4",
//              "frames": "0:300", "args": ["--no-shadows"]}, ...]}
//
// Relative paths are taken from the manifest's folder.
#include "commands.h"
#include "stop_signals.h"

#include "artrace/io/text_file.h"

#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <map>
#include <memory>
#include <stdexcept>
#include <thread>

namespace artrace::tools {
namespace {

struct BatchOptions {
  std::string manifest;
  int parallel = 1, index = -1, threads = 0;
  bool skip_done = false;
};

struct Job {
  std::string recording, scene, output, frames;
  std::vector<std::string> args;
};

std::vector<Job> read_manifest(const std::filesystem::path& file) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(io::read_text_file(file));
  } catch (const nlohmann::json::parse_error& e) {
    throw std::runtime_error(file.string() + ": " + e.what());
  }
  const std::filesystem::path base = file.parent_path();
  auto resolve = [&](const std::string& p) { return std::filesystem::path(p).is_absolute() ? p : (base / p).string(); };
  if (!j.is_object() || !j.contains("jobs") || !j["jobs"].is_array() || j["jobs"].empty()) {
    throw std::runtime_error(file.string() + ": expected {\"jobs\": [...]} with at least one job");
  }
  std::vector<Job> jobs;
  std::map<std::filesystem::path, size_t> writers;  // each output, as one path, and its job
  for (size_t i = 0; i < j["jobs"].size(); ++i) {
    const nlohmann::json& e = j["jobs"][i];
    const std::string where = file.string() + ": jobs[" + std::to_string(i) + "]";
    Job job;
    try {
      for (const char* key : {"recording", "scene", "output"}) {
        if (!e.contains(key) || !e[key].is_string()) throw std::runtime_error(std::string("\"") + key + "\" (a string) is missing");
      }
      for (auto it = e.begin(); it != e.end(); ++it) {
        if (it.key() != "recording" && it.key() != "scene" && it.key() != "output" && it.key() != "frames" && it.key() != "args") {
          throw std::runtime_error("unknown key \"" + it.key() + "\" (recording, scene, output, frames, args)");
        }
      }
      job.recording = resolve(e["recording"].get<std::string>());
      job.scene = resolve(e["scene"].get<std::string>());
      job.output = resolve(e["output"].get<std::string>());
      if (e.contains("frames")) job.frames = e["frames"].get<std::string>();
      if (e.contains("args")) job.args = e["args"].get<std::vector<std::string>>();
      // two jobs with one output: the later overwrote the earlier, or both wrote it at once
      std::filesystem::path key = std::filesystem::weakly_canonical(job.output).lexically_normal();
      if (!key.has_filename()) key = key.parent_path();  // a trailing separator
      const auto [at, first] = writers.emplace(key, i);
      if (!first) {
        throw std::runtime_error("output \"" + e["output"].get<std::string>() + "\" is also jobs[" + std::to_string(at->second) +
                                 "]'s: each job needs an output of its own");
      }
    } catch (const std::exception& ex) {
      throw std::runtime_error(where + ": " + ex.what());
    }
    jobs.push_back(std::move(job));
  }
  return jobs;
}

/// Starts `artrace export` for a job; returns the child's pid.
pid_t start(const Job& job, int threads) {
  std::vector<std::string> argv = {"artrace", "export", job.recording, "--scene", job.scene, "-o", job.output, "-q",
                                   "--threads", std::to_string(threads)};
  if (!job.frames.empty()) argv.insert(argv.end(), {"--frames", job.frames});
  argv.insert(argv.end(), job.args.begin(), job.args.end());
  std::vector<char*> c;
  for (std::string& s : argv) c.push_back(s.data());
  c.push_back(nullptr);
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("batch: cannot start a process");
  if (pid == 0) {
    execv("/proc/self/exe", c.data());
    std::perror("artrace batch: exec");
    _exit(127);
  }
  return pid;
}

/// "0, 2, 5": job numbers in order, for messages.
std::string job_list(std::vector<size_t> jobs) {
  std::sort(jobs.begin(), jobs.end());
  std::string list;
  for (size_t i : jobs) list += (list.empty() ? "" : ", ") + std::to_string(i);
  return list;
}

void run_batch(const BatchOptions& opt) {
  const std::vector<Job> jobs = read_manifest(opt.manifest);
  std::vector<size_t> todo;
  if (opt.index >= 0) {
    if (static_cast<size_t>(opt.index) >= jobs.size()) {
      throw std::invalid_argument(opt.manifest + " has " + std::to_string(jobs.size()) + " jobs; there is no job " + std::to_string(opt.index));
    }
    todo.push_back(static_cast<size_t>(opt.index));
  } else {
    for (size_t i = 0; i < jobs.size(); ++i) todo.push_back(i);
  }
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  const int threads = opt.threads > 0 ? opt.threads : static_cast<int>(std::max(1u, cores / static_cast<unsigned>(opt.parallel)));
  std::map<pid_t, size_t> running;
  std::vector<size_t> failed;
  size_t next = 0, done = 0, skipped = 0;
  const StopSignals signals(/*restart=*/false);  // wait() returns when one comes
  auto reap = [&] {
    int status = 0;
    const pid_t pid = wait(&status);
    if (pid < 0 && errno == EINTR) return;  // a stop signal: the loop passes it on
    if (pid < 0) throw std::runtime_error("batch: lost track of a job");
    const size_t i = running.at(pid);
    running.erase(pid);
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    std::printf("batch: job %zu %s (%s)\n", i, ok ? "done" : "FAILED", jobs[i].output.c_str());
    if (ok) ++done;
    else failed.push_back(i);
  };
  while (next < todo.size() || !running.empty()) {
    if (const int s = StopSignals::caught()) {
      // a stop asked of the batch alone (kill's SIGTERM) goes on to the running jobs, which remove
      // their partial outputs; no more are started. Without it they ran on, orphaned.
      std::vector<size_t> stopped;
      for (const auto& [pid, i] : running) {
        kill(pid, s);
        stopped.push_back(i);
      }
      while (!running.empty()) reap();
      throw std::runtime_error(std::string("batch: stopped by ") + StopSignals::name(s) +
                               (stopped.empty() ? "" : ": jobs " + job_list(stopped) + " stopped") + ", " +
                               std::to_string(todo.size() - next) + " not started");
    }
    if (next < todo.size() && static_cast<int>(running.size()) < opt.parallel) {
      const size_t i = todo[next++];
      if (opt.skip_done && std::filesystem::exists(jobs[i].output)) {
        std::printf("batch: job %zu already done (%s)\n", i, jobs[i].output.c_str());
        ++skipped;
        continue;
      }
      std::printf("batch: job %zu: %s -> %s%s\n", i, jobs[i].recording.c_str(), jobs[i].output.c_str(),
                  jobs[i].frames.empty() ? "" : (" frames " + jobs[i].frames).c_str());
      running[start(jobs[i], threads)] = i;
      continue;
    }
    reap();
  }
  std::printf("batch: %zu done, %zu skipped, %zu failed\n", done, skipped, failed.size());
  if (!failed.empty()) {
    throw std::runtime_error("batch: jobs " + job_list(failed) + " failed (see their messages above)");
  }
}

}  // namespace

void add_batch_command(CLI::App& app) {
  auto opt = std::make_shared<BatchOptions>();
  CLI::App* cmd = app.add_subcommand("batch", "Run the export jobs of a manifest (JSON), one after another or several at once");
  cmd->add_option("manifest", opt->manifest, "{\"jobs\": [{recording, scene, output, frames, args}, ...]}")->required()->check(CLI::ExistingFile);
  cmd->add_option("--parallel", opt->parallel, "jobs at once")->capture_default_str()->check(CLI::Range(1, 256));
  cmd->add_option("--index", opt->index, "run only this job (0-based): one array task of a cluster")->check(CLI::Range(0, 100000000));
  cmd->add_option("--threads", opt->threads, "threads a job (0: the cores shared among the parallel jobs)")->capture_default_str()->check(CLI::Range(0, 1024));
  cmd->add_flag("--skip-done", opt->skip_done, "skip jobs whose output exists (outputs appear only when complete)");
  cmd->callback([opt] { run_batch(*opt); });
}

}  // namespace artrace::tools
