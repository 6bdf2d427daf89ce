//! `terraplan user create|list|token|disable|password`: manage the service's users
//! on its database (the same `--data-dir` / `DATABASE_URL` as `serve`),
//! whether or not a server is running on it. A new API token is printed
//! as the last line of stdout, for scripts.

use std::io::Read;
use std::path::PathBuf;

use clap::{Args, Subcommand};

use super::common::Failure;
use crate::auth::accounts::{self, AccountError};
use crate::auth::password;
use crate::db::Db;

#[derive(Subcommand)]
pub enum UserCommand {
    /// Make a user and its personal project; prints a new API token as
    /// the last line.
    Create(CreateArgs),
    /// List the users: name, admin, disabled, created (UTC).
    List(DbArgs),
    /// Make a new API token for a user; prints it as the last line.
    Token(NameArgs),
    /// Disable a user: its tokens and sessions stop working at once.
    Disable(NameArgs),
    /// Set (or reset) a user's password from the first line of stdin; the
    /// user's web sessions end, its API tokens go on working.
    Password(NameArgs),
}

/// Where the service keeps its data, as for `terraplan serve`.
#[derive(Args)]
pub struct DbArgs {
    /// Directory of the embedded SQLite database.
    #[arg(long, env = "TERRAPLAN_DATA_DIR", default_value = "terraplan-data")]
    data_dir: PathBuf,
    /// `postgres://…` to use PostgreSQL instead of the embedded SQLite
    /// (`sqlite:PATH` is accepted too).
    #[arg(long, env = "DATABASE_URL")]
    database_url: Option<String>,
}

#[derive(Args)]
pub struct CreateArgs {
    /// The user name: 1 to 64 letters, digits, '.', '_' or '-'.
    name: String,
    /// Let the user manage users (not other users' projects).
    #[arg(long)]
    admin: bool,
    /// Read a password (first line of stdin) for signing in to the web
    /// page; without it the user signs in with API tokens only.
    #[arg(long)]
    password_stdin: bool,
    #[command(flatten)]
    db: DbArgs,
}

#[derive(Args)]
pub struct NameArgs {
    /// The user name.
    name: String,
    #[command(flatten)]
    db: DbArgs,
}

pub(super) fn user(command: UserCommand) -> Result<(), Failure> {
    // Read before the runtime starts: the password never waits on the
    // database, and a bad one fails before anything is written.
    let password = match &command {
        UserCommand::Create(args) if args.password_stdin => Some(read_password()?),
        UserCommand::Password(_) => Some(read_password()?),
        _ => None,
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::other(format!("cannot start the async runtime: {e}")))?;
    runtime.block_on(run(command, password))
}

async fn run(command: UserCommand, password: Option<String>) -> Result<(), Failure> {
    match command {
        UserCommand::Create(args) => {
            let db = open(&args.db).await?;
            let made = accounts::create_user(&db, &args.name, password.as_deref(), args.admin)
                .await
                .map_err(failure);
            db.close().await;
            let made = made?;
            println!(
                "made user {:?}{} with personal project {}",
                made.user.name,
                if args.admin { " (admin)" } else { "" },
                made.personal_project_id
            );
            if made.adopted > 0 {
                println!(
                    "moved {} resources made before accounts into its personal project",
                    made.adopted
                );
            }
            println!("API token (shown only now):");
            println!("{}", made.token);
            Ok(())
        }
        UserCommand::List(db_args) => {
            let db = open(&db_args).await?;
            let listed = db.list_users(i64::MAX, 0).await;
            db.close().await;
            let (users, _) = listed.map_err(|e| Failure::other(format!("database: {e}")))?;
            println!("{:<32} {:<5} {:<8} created", "name", "admin", "disabled");
            for u in users {
                println!(
                    "{:<32} {:<5} {:<8} {}",
                    u.name,
                    yes_no(u.admin),
                    yes_no(u.disabled),
                    crate::clock::rfc3339(u.created_at)
                );
            }
            Ok(())
        }
        UserCommand::Token(args) => {
            let db = open(&args.db).await?;
            let made = new_token(&db, &args.name).await;
            db.close().await;
            let token = made?;
            println!("API token for {:?} (shown only now):", args.name);
            println!("{token}");
            Ok(())
        }
        UserCommand::Password(args) => {
            let db = open(&args.db).await?;
            let done = set_password(&db, &args.name, password.as_deref().unwrap_or_default()).await;
            db.close().await;
            done?;
            println!(
                "user {:?} has a new password; its web sessions have ended",
                args.name
            );
            Ok(())
        }
        UserCommand::Disable(args) => {
            let db = open(&args.db).await?;
            let done = disable(&db, &args.name).await;
            db.close().await;
            done?;
            println!(
                "user {:?} is disabled: its tokens and sessions no longer work",
                args.name
            );
            Ok(())
        }
    }
}

async fn new_token(db: &Db, name: &str) -> Result<String, Failure> {
    let user = accounts::user_named(db, name).await.map_err(failure)?;
    if user.disabled != 0 {
        return Err(Failure::input(format!(
            "user {name:?} is disabled: a token of it would not work"
        )));
    }
    let (_, token) = accounts::issue_token(db, &user.id, "made with terraplan user token", None)
        .await
        .map_err(|e| Failure::other(format!("database: {e}")))?;
    Ok(token)
}

async fn disable(db: &Db, name: &str) -> Result<(), Failure> {
    let user = accounts::user_named(db, name).await.map_err(failure)?;
    db.disable_user(&user.id)
        .await
        .map(|_| ())
        .map_err(|e| Failure::other(format!("database: {e}")))
}

async fn set_password(db: &Db, name: &str, password: &str) -> Result<(), Failure> {
    let user = accounts::user_named(db, name).await.map_err(failure)?;
    db.set_password_hash(&user.id, &password::hash(password))
        .await
        .map_err(|e| Failure::other(format!("database: {e}")))
}

fn yes_no(flag: i64) -> &'static str {
    if flag != 0 { "yes" } else { "no" }
}

/// Open (and migrate) the database, making the data directory if needed,
/// so that users can be made before the first `serve`.
async fn open(args: &DbArgs) -> Result<Db, Failure> {
    if args.database_url.is_none() {
        std::fs::create_dir_all(&args.data_dir).map_err(|e| {
            Failure::other(format!(
                "cannot create data directory {}: {e}",
                args.data_dir.display()
            ))
        })?;
    }
    Db::connect(args.database_url.as_deref(), &args.data_dir)
        .await
        .map_err(|e| Failure::other(format!("cannot open the database: {e}")))
}

/// The password on stdin's first line (its line ending removed).
fn read_password() -> Result<String, Failure> {
    let mut text = String::new();
    std::io::stdin()
        .take(password::MAX_BYTES as u64 + 3)
        .read_to_string(&mut text)
        .map_err(|e| Failure::input(format!("cannot read the password from stdin: {e}")))?;
    let line = text.lines().next().unwrap_or("");
    if let Some(fault) = password::fault(line) {
        return Err(Failure::input(format!("--password-stdin: {fault}")));
    }
    Ok(line.to_string())
}

fn failure(e: AccountError) -> Failure {
    match e {
        AccountError::Db(e) => Failure::other(format!("database: {e}")),
        other => Failure::input(other.to_string()),
    }
}
